# Wrapper around CMake. `make run` and `make test` install missing packages first.
BUILD ?= build
ASAN_BUILD ?= build-asan
JOBS ?= $(shell nproc)
SCENE ?= room
OUT ?= hrad-out
PREFIX ?= /usr/local

.PHONY: all setup build run test test-asan bench clean install

all: build

setup:
	@bash scripts/setup.sh

build: setup
	@cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release >/dev/null
	@cmake --build $(BUILD) -j $(JOBS)

run: build
	./$(BUILD)/hrad -o $(OUT) $(SCENE)

# `make install PREFIX=P`: hrad, libhrad.a and libhrad.so, hrad.h, hrad.pc, the CMake package and
# the man page into P (default /usr/local); README "Use it from your pipeline".
install: build
	cmake --install $(BUILD) --prefix $(PREFIX)

test: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

test-asan: setup
	@cmake -S . -B $(ASAN_BUILD) -DCMAKE_BUILD_TYPE=Debug -DHR_SANITIZE=ON >/dev/null
	@cmake --build $(ASAN_BUILD) -j $(JOBS)
	cd $(ASAN_BUILD) && ASAN_OPTIONS=detect_leaks=1 ctest --output-on-failure -j $(JOBS)

bench: build
	bash bench/run.sh $(BUILD)

clean:
	rm -rf $(BUILD) $(ASAN_BUILD) $(OUT)

# Fuzzing and clang UBSan (TESTING.md). `make fuzz` builds the libFuzzer targets of tests/fuzz
# with clang (ASan + UBSan) in FUZZ_BUILD and runs each FUZZ_SECONDS on its corpus; `make
# fuzz-merge` adds what they found that reaches new coverage to the corpora in tests/fuzz.
# `make test-ubsan` runs the whole suite built by clang with -fsanitize=undefined,float-cast-overflow.
FUZZ_BUILD ?= build-fuzz
FUZZ_SECONDS ?= 60
UBSAN_BUILD ?= build-ubsan
CLANG ?= clang

.PHONY: fuzz fuzz-merge test-ubsan clean-fuzz

fuzz: setup
	CLANG=$(CLANG) bash tests/fuzz/run.sh run $(FUZZ_BUILD) $(FUZZ_SECONDS)

fuzz-merge: setup
	CLANG=$(CLANG) bash tests/fuzz/run.sh merge $(FUZZ_BUILD)

test-ubsan:
	@bash scripts/setup.sh --clang
	@cmake -S . -B $(UBSAN_BUILD) -DCMAKE_C_COMPILER=$(CLANG) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DHR_UBSAN_CLANG=ON >/dev/null
	@cmake --build $(UBSAN_BUILD) -j $(JOBS)
	cd $(UBSAN_BUILD) && UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 ctest --output-on-failure -j $(JOBS)

clean-fuzz:
	rm -rf $(FUZZ_BUILD) $(UBSAN_BUILD)
clean: clean-fuzz
