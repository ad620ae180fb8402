/* xorshift.h: the fixed-seed xorshift64 generator of the tests and benchmarks (header-only, one
 * state per program). A program that wants its own sequence sets 'rng_state' (never 0). */
#ifndef HR_XORSHIFT_H
#define HR_XORSHIFT_H

#include <stdint.h>

static uint64_t rng_state = 88172645463325252ull;

static inline uint64_t xorshift(void) {
  uint64_t x = rng_state;
  x ^= x << 13;
  x ^= x >> 7;
  x ^= x << 17;
  return rng_state = x;
}
static inline double rnd(void) { return (double)(xorshift() >> 11) * (1.0 / 9007199254740992.0); }
static inline double rnd_in(double a, double b) { return a + (b - a) * rnd(); }
static inline int rnd_int(int n) { return (int)(xorshift() % (uint64_t)n); }

#endif
