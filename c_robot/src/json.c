#include "json.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void jr_init(JR *r, const void *data, size_t size) {
    r->start = r->p = data;
    r->end = r->p + size;
    r->err = 0;
}

int jr_fail(JR *r) {
    r->err = 1;
    return 0;
}

static void ws(JR *r) {
    while (r->p < r->end && (*r->p == ' ' || *r->p == '\t' || *r->p == '\n' || *r->p == '\r'))
        r->p++;
}

int jr_peek(JR *r) {
    if (r->err) return 0;
    ws(r);
    return r->p < r->end ? *r->p : 0;
}

static int expect(JR *r, int c) {
    if (r->err) return 0;
    ws(r);
    if (r->p >= r->end || *r->p != c) return jr_fail(r);
    r->p++;
    return 1;
}

int jr_obj_begin(JR *r) { return expect(r, '{'); }
int jr_arr_begin(JR *r) { return expect(r, '['); }

int jr_obj_next(JR *r, int *first, char *key, size_t cap) {
    if (r->err) return 0;
    int c = jr_peek(r);
    if (*first) {
        *first = 0;
        if (c == '}') {
            r->p++;
            return 0;
        }
    } else {
        if (c == '}') {
            r->p++;
            return 0;
        }
        if (c != ',') return jr_fail(r);
        r->p++;
        if (jr_peek(r) != '"') return jr_fail(r); /* a trailing comma */
    }
    size_t len, chars;
    if (!jr_string(r, key, cap, &len, &chars)) return 0;
    if (strlen(key) != len) return jr_fail(r); /* a NUL in a key: no field of ours */
    if (!expect(r, ':')) return 0;
    return 1;
}

int jr_arr_next(JR *r, int *first) {
    if (r->err) return 0;
    int c = jr_peek(r);
    if (c == ']') {
        r->p++;
        return 0;
    }
    if (*first) {
        *first = 0;
        return c != 0 ? 1 : jr_fail(r);
    }
    if (c != ',') return jr_fail(r);
    r->p++;
    c = jr_peek(r);
    if (c == ']' || c == 0) return jr_fail(r);
    return 1;
}

/* Scan a number token; sets *is_int; [from, to) its text. */
static int number_token(JR *r, const uint8_t **from, const uint8_t **to, int *is_int) {
    if (r->err) return 0;
    ws(r);
    const uint8_t *p = r->p, *e = r->end;
    *from = p;
    *is_int = 1;
    if (p < e && *p == '-') p++;
    if (p >= e) return jr_fail(r);
    if (*p == '0') {
        p++;
    } else if (*p >= '1' && *p <= '9') {
        while (p < e && *p >= '0' && *p <= '9') p++;
    } else {
        return jr_fail(r);
    }
    if (p < e && *p == '.') {
        *is_int = 0;
        p++;
        if (p >= e || !(*p >= '0' && *p <= '9')) return jr_fail(r);
        while (p < e && *p >= '0' && *p <= '9') p++;
    }
    if (p < e && (*p == 'e' || *p == 'E')) {
        *is_int = 0;
        p++;
        if (p < e && (*p == '+' || *p == '-')) p++;
        if (p >= e || !(*p >= '0' && *p <= '9')) return jr_fail(r);
        while (p < e && *p >= '0' && *p <= '9') p++;
    }
    /* a number runs into a letter or digit: "01", "1x" */
    if (p < e && ((*p >= '0' && *p <= '9') || *p == '.' || *p == '-' || *p == '+' ||
                  (*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z')))
        return jr_fail(r);
    *to = p;
    r->p = p;
    return 1;
}

int jr_int(JR *r, int64_t *out) {
    const uint8_t *from, *to;
    int is_int;
    if (!number_token(r, &from, &to, &is_int)) return 0;
    if (!is_int) return jr_fail(r);
    const uint8_t *p = from;
    int negative = 0;
    if (*p == '-') {
        negative = 1;
        p++;
    }
    uint64_t value = 0;
    for (; p < to; p++) {
        uint64_t digit = (uint64_t)(*p - '0');
        if (value > (UINT64_MAX - digit) / 10) return jr_fail(r);
        value = value * 10 + digit;
    }
    if (negative) {
        if (value > (uint64_t)INT64_MAX + 1) return jr_fail(r);
        *out = value == (uint64_t)INT64_MAX + 1 ? INT64_MIN : -(int64_t)value;
    } else {
        if (value > (uint64_t)INT64_MAX) return jr_fail(r);
        *out = (int64_t)value;
    }
    return 1;
}

int jr_float(JR *r, double *out) {
    const uint8_t *from, *to;
    int is_int;
    if (!number_token(r, &from, &to, &is_int)) return 0;
    char text[400];
    size_t n = (size_t)(to - from);
    if (is_int && n <= 19) {
        /* an integer converts as msgspec converts one: (double)int, so -0 is 0.0 */
        const uint8_t *p = from;
        int negative = *p == '-';
        if (negative) p++;
        uint64_t value = 0;
        for (; p < to; p++) value = value * 10 + (uint64_t)(*p - '0');
        if (value <= (uint64_t)INT64_MAX) {
            double d = (double)(int64_t)value;
            *out = negative ? -d : d;
            if (*out == 0.0) *out = 0.0;
            return 1;
        }
    }
    double value;
    if (n < sizeof text) {
        memcpy(text, from, n);
        text[n] = 0;
        value = strtod(text, NULL);
    } else {
        /* a long number: keep the sign, the first digits and the exponent right */
        return jr_fail(r);
    }
    if (!isfinite(value)) return jr_fail(r);
    *out = value;
    return 1;
}

static int literal(JR *r, const char *word) {
    if (r->err) return 0;
    ws(r);
    size_t n = strlen(word);
    if ((size_t)(r->end - r->p) < n || memcmp(r->p, word, n) != 0) return jr_fail(r);
    r->p += n;
    if (r->p < r->end && ((*r->p >= 'a' && *r->p <= 'z') || (*r->p >= '0' && *r->p <= '9')))
        return jr_fail(r);
    return 1;
}

int jr_bool(JR *r, int *out) {
    int c = jr_peek(r);
    if (c == 't') {
        *out = 1;
        return literal(r, "true");
    }
    if (c == 'f') {
        *out = 0;
        return literal(r, "false");
    }
    return jr_fail(r);
}

int jr_null(JR *r) {
    if (jr_peek(r) == 'n') return literal(r, "null");
    return 0;
}

static int hex4(const uint8_t *p, unsigned *out) {
    unsigned v = 0;
    for (int i = 0; i < 4; i++) {
        int c = p[i];
        v <<= 4;
        if (c >= '0' && c <= '9') v |= (unsigned)(c - '0');
        else if (c >= 'a' && c <= 'f') v |= (unsigned)(c - 'a' + 10);
        else if (c >= 'A' && c <= 'F') v |= (unsigned)(c - 'A' + 10);
        else return 0;
    }
    *out = v;
    return 1;
}

static int put_utf8(char *buf, size_t cap, size_t *len, unsigned cp) {
    uint8_t tmp[4];
    int n;
    if (cp < 0x80) { tmp[0] = (uint8_t)cp; n = 1; }
    else if (cp < 0x800) { tmp[0] = (uint8_t)(0xC0 | cp >> 6); tmp[1] = (uint8_t)(0x80 | (cp & 0x3F)); n = 2; }
    else if (cp < 0x10000) { tmp[0] = (uint8_t)(0xE0 | cp >> 12); tmp[1] = (uint8_t)(0x80 | ((cp >> 6) & 0x3F)); tmp[2] = (uint8_t)(0x80 | (cp & 0x3F)); n = 3; }
    else { tmp[0] = (uint8_t)(0xF0 | cp >> 18); tmp[1] = (uint8_t)(0x80 | ((cp >> 12) & 0x3F)); tmp[2] = (uint8_t)(0x80 | ((cp >> 6) & 0x3F)); tmp[3] = (uint8_t)(0x80 | (cp & 0x3F)); n = 4; }
    if (*len + (size_t)n >= cap) return 0;
    memcpy(buf + *len, tmp, (size_t)n);
    *len += (size_t)n;
    return 1;
}

/* One UTF-8 sequence at p (strict: no overlongs, surrogates or values past U+10FFFF). */
static int utf8_sequence(const uint8_t *p, const uint8_t *e, unsigned *cp) {
    uint8_t c = p[0];
    if (c < 0x80) { *cp = c; return 1; }
    int n;
    unsigned v, min;
    if ((c & 0xE0) == 0xC0) { n = 2; v = c & 0x1F; min = 0x80; }
    else if ((c & 0xF0) == 0xE0) { n = 3; v = c & 0x0F; min = 0x800; }
    else if ((c & 0xF8) == 0xF0) { n = 4; v = c & 0x07; min = 0x10000; }
    else return 0;
    if (e - p < n) return 0;
    for (int i = 1; i < n; i++) {
        if ((p[i] & 0xC0) != 0x80) return 0;
        v = v << 6 | (p[i] & 0x3F);
    }
    if (v < min || v > 0x10FFFF || (v >= 0xD800 && v <= 0xDFFF)) return 0;
    *cp = v;
    return n;
}

int jr_string(JR *r, char *buf, size_t cap, size_t *len, size_t *chars) {
    if (!expect(r, '"')) return 0;
    *len = 0;
    *chars = 0;
    const uint8_t *p = r->p, *e = r->end;
    while (1) {
        if (p >= e) return jr_fail(r);
        uint8_t c = *p;
        if (c == '"') {
            p++;
            break;
        }
        if (c < 0x20) return jr_fail(r);
        if (c == '\\') {
            if (e - p < 2) return jr_fail(r);
            uint8_t k = p[1];
            unsigned cp;
            p += 2;
            switch (k) {
            case '"': cp = '"'; break;
            case '\\': cp = '\\'; break;
            case '/': cp = '/'; break;
            case 'b': cp = 8; break;
            case 'f': cp = 12; break;
            case 'n': cp = 10; break;
            case 'r': cp = 13; break;
            case 't': cp = 9; break;
            case 'u':
                if (e - p < 4 || !hex4(p, &cp)) return jr_fail(r);
                p += 4;
                if (cp >= 0xD800 && cp <= 0xDBFF) {
                    unsigned low;
                    if (e - p < 6 || p[0] != '\\' || p[1] != 'u' || !hex4(p + 2, &low) ||
                        low < 0xDC00 || low > 0xDFFF)
                        return jr_fail(r);
                    p += 6;
                    cp = 0x10000 + ((cp - 0xD800) << 10) + (low - 0xDC00);
                } else if (cp >= 0xDC00 && cp <= 0xDFFF) {
                    return jr_fail(r);
                }
                break;
            default:
                return jr_fail(r);
            }
            if (!put_utf8(buf, cap, len, cp)) return jr_fail(r);
            (*chars)++;
            continue;
        }
        unsigned cp;
        int n = utf8_sequence(p, e, &cp);
        if (n == 0) return jr_fail(r);
        if (*len + (size_t)n >= cap) return jr_fail(r);
        memcpy(buf + *len, p, (size_t)n);
        *len += (size_t)n;
        (*chars)++;
        p += n;
    }
    buf[*len] = 0;
    r->p = p;
    return 1;
}

static int skip_depth(JR *r, int depth) {
    if (depth > 64) return jr_fail(r);
    int c = jr_peek(r);
    if (c == '{') {
        r->p++;
        int first = 1;
        char key[256];
        while (jr_obj_next(r, &first, key, sizeof key))
            if (!skip_depth(r, depth + 1)) return 0;
        return !r->err;
    }
    if (c == '[') {
        r->p++;
        int first = 1;
        while (jr_arr_next(r, &first))
            if (!skip_depth(r, depth + 1)) return 0;
        return !r->err;
    }
    if (c == '"') {
        /* validate without keeping */
        char tmp[8];
        size_t len = 0, chars = 0;
        if (!expect(r, '"')) return 0;
        r->p--;
        const uint8_t *save = r->p;
        (void)save;
        /* walk it: reuse jr_string piecewise is awkward; scan directly */
        const uint8_t *p = r->p + 1, *e = r->end;
        while (1) {
            if (p >= e) return jr_fail(r);
            if (*p == '"') { p++; break; }
            if (*p < 0x20) return jr_fail(r);
            if (*p == '\\') {
                if (e - p < 2) return jr_fail(r);
                if (p[1] == 'u') {
                    unsigned cp;
                    if (e - p < 6 || !hex4(p + 2, &cp)) return jr_fail(r);
                    p += 6;
                } else if (strchr("\"\\/bfnrt", p[1]) && p[1]) {
                    p += 2;
                } else {
                    return jr_fail(r);
                }
                continue;
            }
            unsigned cp;
            int n = utf8_sequence(p, e, &cp);
            if (n == 0) return jr_fail(r);
            p += n;
        }
        (void)tmp; (void)len; (void)chars;
        r->p = p;
        return 1;
    }
    if (c == 't' || c == 'f') {
        int b;
        return jr_bool(r, &b);
    }
    if (c == 'n') return jr_null(r);
    double d;
    return jr_float(r, &d);
}

int jr_skip(JR *r, const uint8_t **from, const uint8_t **to) {
    jr_peek(r);
    *from = r->p;
    if (!skip_depth(r, 0)) return 0;
    *to = r->p;
    return 1;
}

int jr_end(JR *r) {
    if (r->err) return 0;
    ws(r);
    if (r->p != r->end) return jr_fail(r);
    return 1;
}

/* --- writer ------------------------------------------------------------------------- */

void jw_init(JW *w, void *buf, size_t cap) {
    w->buf = buf;
    w->cap = cap;
    w->len = 0;
    w->err = 0;
}

void jw_bytes(JW *w, const void *data, size_t size) {
    if (w->err) return;
    if (w->len + size > w->cap) {
        w->err = 1;
        return;
    }
    memcpy(w->buf + w->len, data, size);
    w->len += size;
}

void jw_raw(JW *w, const char *text) { jw_bytes(w, text, strlen(text)); }

int format_int(int64_t value, char out[21]) {
    /* by hand: newlib-nano's printf has no %lld */
    char digits[20];
    uint64_t magnitude = value < 0 ? 0 - (uint64_t)value : (uint64_t)value;
    int n = 0, o = 0;
    do {
        digits[n++] = (char)('0' + magnitude % 10);
        magnitude /= 10;
    } while (magnitude);
    if (value < 0) out[o++] = '-';
    while (n) out[o++] = digits[--n];
    out[o] = 0;
    return o;
}

void jw_int(JW *w, int64_t value) {
    char text[21];
    jw_bytes(w, text, (size_t)format_int(value, text));
}

void jw_bool(JW *w, int value) { jw_raw(w, value ? "true" : "false"); }

void jw_float(JW *w, double value) {
    char text[64];
    int n = format_double(value, text, sizeof text);
    if (n <= 0) {
        w->err = 1;
        return;
    }
    jw_bytes(w, text, (size_t)n);
}

void jw_str(JW *w, const char *text, size_t size) {
    static const char hexd[] = "0123456789abcdef";
    jw_bytes(w, "\"", 1);
    for (size_t i = 0; i < size; i++) {
        unsigned char c = (unsigned char)text[i];
        char esc[8];
        if (c == '"') jw_bytes(w, "\\\"", 2);
        else if (c == '\\') jw_bytes(w, "\\\\", 2);
        else if (c == '\n') jw_bytes(w, "\\n", 2);
        else if (c == '\r') jw_bytes(w, "\\r", 2);
        else if (c == '\t') jw_bytes(w, "\\t", 2);
        else if (c == '\b') jw_bytes(w, "\\b", 2);
        else if (c == '\f') jw_bytes(w, "\\f", 2);
        else if (c < 0x20) {
            esc[0] = '\\'; esc[1] = 'u'; esc[2] = '0'; esc[3] = '0';
            esc[4] = hexd[c >> 4]; esc[5] = hexd[c & 15];
            jw_bytes(w, esc, 6);
        } else jw_bytes(w, &text[i], 1);
    }
    jw_bytes(w, "\"", 1);
}

void jw_key(JW *w, const char *key, int first) {
    if (!first) jw_bytes(w, ",", 1);
    jw_str(w, key, strlen(key));
    jw_bytes(w, ":", 1);
}

/* The shortest decimal digits that read back to value (> 0, finite): digits (no dot)
   and the decimal exponent of the first digit. Ties go to the nearest. */
static int shortest(double value, char *digits, int *exponent) {
    char text[40];
    for (int precision = 1; precision <= 17; precision++) {
        snprintf(text, sizeof text, "%.*e", precision - 1, value);
        if (strtod(text, NULL) == value) {
            char *e = strchr(text, 'e');
            int n = 0;
            for (char *p = text; p < e; p++)
                if (*p != '.') digits[n++] = *p;
            digits[n] = 0;
            *exponent = atoi(e + 1);
            return n;
        }
        /* the correctly rounded digits fall just outside the interval of values that
           read back (a power of two, whose interval is lopsided): try the neighbours */
        char *e = strchr(text, 'e');
        char base[20];
        int n = 0;
        for (char *p = text; p < e; p++)
            if (*p != '.') base[n++] = *p;
        base[n] = 0;
        int exp10 = atoi(e + 1);
        for (int direction = 1; direction >= -1; direction -= 2) {
            char cand[20];
            memcpy(cand, base, (size_t)n + 1);
            int cexp = exp10;
            int i = n - 1;
            if (direction > 0) {
                while (i >= 0 && cand[i] == '9') cand[i--] = '0';
                if (i < 0) {
                    memmove(cand + 1, cand, (size_t)n);
                    cand[0] = '1';
                    cand[n] = 0; /* keep n digits: the last is a 0 that carries nothing */
                    cexp++;
                } else {
                    cand[i]++;
                }
            } else {
                while (i >= 0 && cand[i] == '0') cand[i--] = '9';
                if (i < 0 || (i == 0 && cand[0] == '1' && n > 1 && 0)) continue;
                cand[i]--;
                if (cand[0] == '0') continue; /* would lose a digit: not this precision */
            }
            char probe[48];
            snprintf(probe, sizeof probe, "%c.%se%d", cand[0], n > 1 ? cand + 1 : "0", cexp);
            if (strtod(probe, NULL) == value) {
                /* strip trailing zeros */
                int m = n;
                while (m > 1 && cand[m - 1] == '0') m--;
                memcpy(digits, cand, (size_t)m);
                digits[m] = 0;
                *exponent = cexp;
                return m;
            }
        }
    }
    return 0;
}

int format_double(double value, char *out, size_t cap) {
    if (!isfinite(value) || cap < 40) return -1;
    char *o = out;
    if (signbit(value)) {
        *o++ = '-';
        value = -value;
    }
    if (value == 0.0) {
        strcpy(o, "0.0");
        return (int)(o - out) + 3;
    }
    char digits[24];
    int exponent;
    int n = shortest(value, digits, &exponent);
    if (n <= 0) return -1;
    if (exponent >= -5 && exponent < 16) {
        if (exponent >= 0) {
            for (int i = 0; i <= exponent; i++) *o++ = i < n ? digits[i] : '0';
            *o++ = '.';
            if (n > exponent + 1) {
                for (int i = exponent + 1; i < n; i++) *o++ = digits[i];
            } else {
                *o++ = '0';
            }
        } else {
            *o++ = '0';
            *o++ = '.';
            for (int i = 0; i < -exponent - 1; i++) *o++ = '0';
            for (int i = 0; i < n; i++) *o++ = digits[i];
        }
        *o = 0;
    } else {
        *o++ = digits[0];
        if (n > 1) {
            *o++ = '.';
            for (int i = 1; i < n; i++) *o++ = digits[i];
        }
        o += sprintf(o, "e%d", exponent);
    }
    return (int)(o - out);
}

double round_significant9(double value) {
    char text[48];
    snprintf(text, sizeof text, "%.9g", value);
    return strtod(text, NULL);
}
