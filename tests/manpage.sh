#!/usr/bin/env bash
# manpage.sh HRAD SRC [SHARED]: docs/hrad.1 renders without a groff warning and its OPTIONS
# section documents exactly the options `hrad --help` lists (both ways), and `hrad --version`
# prints "hrad MAJOR.MINOR.PATCH".
set -u
hrad=$1 src=$2
man=$src/docs/hrad.1
fail=0
bad() { echo "FAIL: $*"; fail=1; }

warn=$(groff -man -Tutf8 -ww -z "$man" 2>&1)
[ -z "$warn" ] || bad "groff warnings: $warn"

# Options from --help: the tokens on the lines that define options (two spaces, then '-').
help_opts=$("$hrad" --help | grep -E '^  -' | grep -oE '(^|[ ,])--?[a-z][a-z-]*' |
            tr -d ' ,' | sort -u)
# Options from the man page: every option named in the rendered OPTIONS section.
man_opts=$(groff -man -Tutf8 -P-cbou "$man" 2>/dev/null |
           sed -n '/^OPTIONS/,/^ENVIRONMENT/p' | grep -oE '(^|[ ,(])--?[a-z][a-z-]*' |
           tr -d ' ,(' | sort -u)
nhelp=$(echo "$help_opts" | wc -l)
[ "$nhelp" -ge 30 ] || bad "only $nhelp options found in --help (parsing broken?)"
missing=$(comm -23 <(echo "$help_opts") <(echo "$man_opts"))
extra=$(comm -13 <(echo "$help_opts") <(echo "$man_opts"))
[ -z "$missing" ] || bad "in --help but not in docs/hrad.1: $(echo $missing)"
[ -z "$extra" ] || bad "in docs/hrad.1 but not in --help: $(echo $extra)"

v=$("$hrad" --version)
echo "$v" | grep -qE '^hrad [0-9]+\.[0-9]+\.[0-9]+$' || bad "--version printed '$v'"

[ $fail = 0 ] && echo "manpage: $nhelp options documented in --help and docs/hrad.1; $v"
exit $fail
