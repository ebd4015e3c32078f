/* tools/fmtcheck.c: checks output.c's exact %.8f formatter against the C library's printf, and its reader of
 * reals (io_parse_real) against strtod.
 *
 * usage: tools/fmtcheck [COUNT]   (COUNT random doubles of each kind, default 1000000)
 *
 * Links the I/O layer's objects and formats one-disk states with io_format_line, four reals per line, comparing each line
 * with snprintf("%lld %lld %.8f %.8f %.8f %.8f\n"). Values: random bit patterns (every magnitude,
 * subnormals, both signs), random values near 1, dyadic values k/2^n, exact decimal ties at the 8th
 * digit (odd multiples of 2^-9), carries (x.999999995...), -0.0, tiny negatives, huge values, the
 * 2^64 boundary where io.c hands over to printf, inf and nan. Each formatted real is also read back
 * by io_parse_real and compared with strtod, bit for bit, and so are random decimal strings of 1 to 25
 * digits with and without a point, a sign or an exponent (io_parse_real's shortcut and its hand-over
 * to strtod). Prints one summary line; exits 1 on the first mismatch, printing both.
 */
#include "../io.h"

#include <float.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static uint64_t rng = 0x243f6a8885a308d3u;

static uint64_t next_u64(void)
{
    uint64_t z = (rng += 0x9e3779b97f4a7c15u);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9u;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebu;
    return z ^ (z >> 31);
}

static double from_bits(uint64_t b)
{
    double d;
    memcpy(&d, &b, sizeof d);
    return d;
}

static unsigned long long read_checked;

/* io_parse_real(s) is strtod(s), bit for bit, where s is a finite real in range */
static void check_read(const char *s)
{
    double mine = 0, libc = strtod(s, NULL);
    int rc = io_parse_real(s, &mine);
    if (!(libc - libc == 0)) return; /* inf, nan: refused by the reader, by design */
    if (rc != 0 || memcmp(&mine, &libc, sizeof mine) != 0) {
        printf("FAIL: '%s' read as %a (status %d), strtod %a\n", s, mine, rc, libc);
        exit(1);
    }
    read_checked++;
}

static double pending[4];
static int npending;
static unsigned long long checked;

static void flush_line(void)
{
    static double x[1], y[1], vx[1], vy[1];
    static int32_t pc[1], wc[1];
    Sim sim = {x, y, vx, vy, pc, wc, NULL, NULL};
    char mine[IO_LINE_MAX], libc[IO_LINE_MAX];
    x[0] = pending[0], y[0] = pending[1], vx[0] = pending[2], vy[0] = pending[3];
    int64_t step = (int64_t)(next_u64() >> 33);
    size_t len = io_format_line(mine, step, 0, &sim, 0, 0);
    mine[len] = '\0';
    snprintf(libc, sizeof libc, "%lld %lld %.8f %.8f %.8f %.8f\n", (long long)step, 0LL, x[0], y[0],
             vx[0], vy[0]);
    if (strcmp(mine, libc) != 0) {
        printf("FAIL: values %a %a %a %a\n  io.c:   %s  printf: %s", x[0], y[0], vx[0], vy[0], mine,
               libc);
        exit(1);
    }
    checked += 4;
    npending = 0;
    /* the four reals read back as strtod reads them */
    char *tok = strtok(libc, " \n");
    for (int k = 0; tok; k++, tok = strtok(NULL, " \n"))
        if (k >= 2) check_read(tok);
}

static void check(double v)
{
    pending[npending++] = v;
    if (npending == 4) flush_line();
}

static void check_both_signs(double v)
{
    check(v);
    check(-v);
}

int main(int argc, char **argv)
{
    long count = argc > 1 ? atol(argv[1]) : 1000000;
    if (count < 1) count = 1;

    /* special values */
    const double special[] = {0.0,     5e-9,    4.9999999999e-9, 5.0000000001e-9, 1e-8,    0.5,
                              1.0,     1.5,     2.5,     0.125,   0.005,   0.995,   9.999999995,
                              0.999999995,      0.999999996,     99999999.999999995,
                              DBL_MIN, 4.9406564584124654e-324, DBL_MAX, 1e300,   1e22,    1e23,
                              18446744073709551616.0, 18446744073709549568.0,
                              9223372036854775808.0,  36893488147419103232.0, INFINITY, NAN};
    for (size_t k = 0; k < sizeof special / sizeof special[0]; k++) check_both_signs(special[k]);
    /* every power of two, and its neighbours */
    for (int e = -1074; e <= 1023; e++) {
        double p = ldexp(1.0, e);
        check_both_signs(p);
        check_both_signs(nextafter(p, 0));
        check_both_signs(nextafter(p, INFINITY));
    }
    /* every power of ten, and its neighbours */
    for (int e = -30; e <= 30; e++) {
        double p = pow(10.0, e);
        check_both_signs(p);
        check_both_signs(nextafter(p, 0));
        check_both_signs(nextafter(p, INFINITY));
    }
    /* exact ties at the 8th decimal: odd multiples of 2^-9 (x.xxxxxxxx5 exactly), and their
     * neighbours one ulp away, small and large */
    for (long k = 0; k < count / 4; k++) {
        uint64_t u = next_u64();
        double t = ldexp((double)((u >> 11) | 1), -9 - (int)(u % 44));
        double tie = ldexp((double)(2 * (long long)(u >> 34) + 1), -9);
        check(tie);
        check(-tie);
        check(nextafter(tie, 0));
        check(nextafter(tie, INFINITY));
        check((u & 1) ? t : -t);
    }
    /* dyadic values k / 2^n */
    for (long k = 0; k < count / 4; k++) {
        uint64_t u = next_u64();
        double v = ldexp((double)(u >> (11 + u % 53)), -(int)((u >> 8) % 70));
        check((u >> 7) & 1 ? v : -v);
    }
    /* random bit patterns: every exponent, subnormals, both signs */
    for (long k = 0; k < count; k++) {
        double v = from_bits(next_u64());
        if (v == v) check(v);
    }
    /* random values of every decimal magnitude from 1e-12 to 1e20 (the ones simulations print) */
    for (long k = 0; k < count; k++) {
        uint64_t u = next_u64();
        double v = (double)(u >> 11) / 9007199254740992.0 * pow(10.0, (double)(int)(u % 33) - 12);
        check((u >> 5) & 1 ? v : -v);
    }
    /* tiny negatives that round to -0.00000000 */
    for (long k = 0; k < count / 8; k++) {
        uint64_t u = next_u64();
        check(-(double)(u >> 11) / 9007199254740992.0 * 1e-8);
    }
    while (npending) check(0.0);
    /* random decimal strings: 1 to 25 digits, a point or not, signs, some exponents */
    for (long k = 0; k < count; k++) {
        char s[64], *p = s;
        uint64_t u = next_u64();
        int digits = 1 + (int)(u % 25), point = (int)((u >> 5) % (unsigned)(digits + 2)) - 1;
        if ((u >> 10) & 1) *p++ = (u >> 11) & 1 ? '-' : '+';
        for (int d = 0; d < digits; d++) {
            if (d == point) *p++ = '.';
            *p++ = (char)('0' + next_u64() % 10);
        }
        if ((u >> 12) % 16 == 0) p += sprintf(p, "e%d", (int)((u >> 16) % 41) - 20);
        *p = '\0';
        check_read(s);
    }
    printf("fmtcheck: %llu values formatted exactly as printf(\"%%.8f\"), %llu reals read exactly as strtod\n",
           checked, read_checked);
    return 0;
}
