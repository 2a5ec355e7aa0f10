/* numeric.json, rng.json (bit for bit), math.fsum and the float spelling. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "json.h"
#include "numeric.h"
#include "rng.h"
#include "tests.h"

static double bits(const char *hex) {
    if (!strcmp(hex, "nan")) return NAN;
    unsigned long long v = strtoull(hex, NULL, 16);
    double d;
    memcpy(&d, &v, 8);
    return d;
}

static int same(double got, const char *hex) {
    if (!strcmp(hex, "nan")) return isnan(got);
    unsigned long long v;
    memcpy(&v, &got, 8);
    return v == strtoull(hex, NULL, 16);
}

void test_numeric(void) {
    JNode *root = load("numeric.json");
    if (!root) return;
    JNode *cases = jdom_get(root, "cases");
    for (size_t f = 0; f < cases->count; f++) {
        const char *fn = cases->keys[f];
        JNode *list = cases->items[f];
        for (size_t i = 0; i < list->count; i++) {
            JNode *c = list->items[i];
            JNode *in = jdom_get(c, "in"), *out = jdom_get(c, "out");
            double a = bits(in->items[0]->str);
            double b = in->count > 1 ? bits(in->items[1]->str) : 0.0;
            int ok;
            if (!strcmp(fn, "sincos")) {
                double s, co;
                nk_sincos(a, &s, &co);
                ok = same(s, out->items[0]->str) && same(co, out->items[1]->str);
            } else if (!strcmp(fn, "atan")) ok = same(nk_atan(a), out->items[0]->str);
            else if (!strcmp(fn, "atan2")) ok = same(nk_atan2(a, b), out->items[0]->str);
            else if (!strcmp(fn, "exp")) ok = same(nk_exp(a), out->items[0]->str);
            else if (!strcmp(fn, "log")) ok = same(nk_log(a), out->items[0]->str);
            else if (!strcmp(fn, "power")) ok = same(nk_power(a, b), out->items[0]->str);
            else if (!strcmp(fn, "wrap_angle")) ok = same(nk_wrap_angle(a), out->items[0]->str);
            else ok = 0;
            char name[128];
            snprintf(name, sizeof name, "%s(%s)", fn, in->items[0]->str);
            check(ok, "numeric.json", name);
        }
    }
    /* cos alone, as the navigator calls it */
    double s, c;
    nk_sincos(2.5, &s, &c);
    check(nk_cos(2.5) == c, "numeric", "cos is sincos's second half");
}

static unsigned long long hexu(const char *hex) { return strtoull(hex, NULL, 16); }

void test_rng(void) {
    JNode *root = load("rng.json");
    if (!root) return;
    JNode *cases = jdom_get(root, "cases");
    for (size_t i = 0; i < cases->count; i++) {
        JNode *c = cases->items[i];
        Stream st;
        stream_seed(&st, hexu(jdom_str(c, "seed")));
        JNode *calls = jdom_get(c, "calls"), *returns = jdom_get(c, "returns");
        int ok = 1;
        for (size_t k = 0; k < calls->count; k++) {
            const char *call = calls->items[k]->items[0]->str;
            JNode *args = calls->items[k]->items[1];
            JNode *want = returns->items[k];
            if (!strcmp(call, "next_u64")) ok &= stream_next_u64(&st) == hexu(want->str);
            else if (!strcmp(call, "random")) ok &= same(stream_random(&st), want->str);
            else if (!strcmp(call, "uniform"))
                ok &= same(stream_uniform(&st, args->items[0]->num, args->items[1]->num), want->str);
            else if (!strcmp(call, "randrange"))
                ok &= stream_randrange(&st, (unsigned long long)args->items[0]->integer) ==
                      (unsigned long long)want->integer;
            else if (!strcmp(call, "choice")) {
                JNode *items = args->items[0];
                JNode *got = items->items[stream_randrange(&st, items->count)];
                ok &= got->type == want->type &&
                      (got->type == J_STR ? !strcmp(got->str, want->str) : got->integer == want->integer);
            } else if (!strcmp(call, "expovariate"))
                ok &= same(stream_expovariate(&st, args->items[0]->num), want->str);
            else if (!strcmp(call, "normal")) ok &= same(stream_normal(&st), want->str);
            else if (!strcmp(call, "fork")) {
                Stream child;
                stream_fork(&st, &child);
                ok &= child.state == hexu(want->str);
            } else if (!strcmp(call, "shuffle")) {
                JNode *items = args->items[0];
                long long v[64];
                for (size_t m = 0; m < items->count; m++) v[m] = items->items[m]->integer;
                stream_shuffle(&st, (int64_t *)v, (int)items->count);
                for (size_t m = 0; m < items->count; m++) ok &= v[m] == want->items[m]->integer;
            } else if (!strcmp(call, "sample")) {
                JNode *items = args->items[0];
                long long p[64];
                size_t count = (size_t)args->items[1]->integer, len = items->count;
                for (size_t m = 0; m < len; m++) p[m] = items->items[m]->integer;
                for (size_t m = 0; m < count; m++) {
                    size_t j = m + stream_randrange(&st, len - m);
                    long long t = p[m]; p[m] = p[j]; p[j] = t;
                }
                for (size_t m = 0; m < count; m++) ok &= p[m] == want->items[m]->integer;
            } else {
                ok = 0;
            }
        }
        ok &= st.state == hexu(jdom_str(c, "state_after"));
        check(ok, "rng.json", jdom_str(c, "name"));
    }
    JNode *seeds = jdom_get(root, "seed_of");
    for (size_t i = 0; i < seeds->count; i++) {
        JNode *s = seeds->items[i];
        char text[256];
        int n = format_int(jdom_get(s, "run_seed")->integer, text); /* nano has no %lld */
        JNode *parts = jdom_get(s, "parts");
        for (size_t k = 0; k < parts->count; k++) {
            JNode *p = parts->items[k];
            n += snprintf(text + n, sizeof text - (size_t)n, ":%s", p->str);
        }
        check(seed_of_text(text) == hexu(jdom_str(s, "seed")), "rng.json seed_of", text);
    }
    /* docs/porting.md's examples */
    check(seed_of_robot(0, 3) == 13239654664643467700ULL, "porting.md", "seed_of(0, robot, 3)");
    check(seed_of_robot(42, 0) == 12090959199918197150ULL, "porting.md", "seed_of(42, robot, 0)");
}

/* cases.json (made by c_robot/tests/make_cases.py from CPython and msgspec) */
void test_fsum(void) {
    JNode *root = cases_json();
    if (!root) {
        check(0, "cases.json", "missing (run from c_robot/)");
        return;
    }
    JNode *cases = jdom_get(root, "fsum");
    for (size_t i = 0; i < cases->count; i++) {
        JNode *c = cases->items[i];
        JNode *in = jdom_get(c, "in");
        double v[2000];
        for (size_t k = 0; k < in->count; k++) v[k] = bits(in->items[k]->str);
        double got;
        int rc = nk_fsum(v, (int)in->count, &got);
        const char *want = jdom_str(c, "out");
        int ok = !strcmp(want, "overflow") ? rc == -1 : rc == 0 && same(got, want);
        char name[64];
        snprintf(name, sizeof name, "fsum case %zu", i);
        check(ok, "fsum", name);
    }
}

void test_format(void) {
    JNode *root = cases_json();
    if (!root) return;
    JNode *cases = jdom_get(root, "format");
    for (size_t i = 0; i < cases->count; i++) {
        JNode *c = cases->items[i];
        double x = bits(jdom_str(c, "in"));
        char text[64];
        format_double(x, text, sizeof text);
        const char *want = jdom_str(c, "msgspec");
        check(!strcmp(text, want), "format (msgspec)", want);
        double nine = round_significant9(x);
        check(same(nine, jdom_str(c, "wire9")), "wire_opinion", want);
        double r = nk_round_half_even(x * 1000.0);
        check(same(r, jdom_str(c, "round1000")), "round()", want);
    }
}
