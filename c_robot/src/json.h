/* A strict JSON reader and a writer, for exactly the project's messages (no malloc).
   The reader accepts what msgspec accepts: any whitespace and field order, integers for
   floats, escapes; it refuses NaN/Infinity, overflowing numbers, trailing characters,
   control characters and invalid UTF-8 in strings. */
#ifndef CR_JSON_H
#define CR_JSON_H
#include <stddef.h>
#include <stdint.h>

typedef struct {
    const uint8_t *start;
    const uint8_t *p;
    const uint8_t *end;
    int err; /* set on the first error; every call then fails */
} JR;

void jr_init(JR *r, const void *data, size_t size);
int jr_fail(JR *r);
/* the next non-whitespace byte, or 0 at the end */
int jr_peek(JR *r);
int jr_obj_begin(JR *r);
/* 1: a key was read into key (NUL-terminated, truncated keys fail); 0: the object ended */
int jr_obj_next(JR *r, int *first, char *key, size_t cap);
int jr_arr_begin(JR *r);
int jr_arr_next(JR *r, int *first); /* 1: an element follows; 0: the array ended */
int jr_int(JR *r, int64_t *out);   /* an integer token, within int64 */
int jr_float(JR *r, double *out);  /* a number (integer or not), finite */
int jr_bool(JR *r, int *out);
int jr_null(JR *r);                /* 1 and consumed when the value is null */
/* a string; its UTF-8 bytes into buf (cap bytes, NUL added), chars = code points */
int jr_string(JR *r, char *buf, size_t cap, size_t *len, size_t *chars);
/* skip any value; its bytes are [*from, *to) */
int jr_skip(JR *r, const uint8_t **from, const uint8_t **to);
int jr_end(JR *r); /* only whitespace left */

typedef struct {
    char *buf;
    size_t cap;
    size_t len;
    int err;
} JW;

void jw_init(JW *w, void *buf, size_t cap);
void jw_raw(JW *w, const char *text);
void jw_bytes(JW *w, const void *data, size_t size);
void jw_int(JW *w, int64_t value);
/* value in decimal, as %lld writes it; returns the length */
int format_int(int64_t value, char out[21]);
void jw_float(JW *w, double value); /* msgspec's spelling: shortest, 1.0, 1e16, 1.5e-7 */
void jw_bool(JW *w, int value);
void jw_str(JW *w, const char *text, size_t size);
void jw_key(JW *w, const char *key, int first); /* ,"key": */

/* shortest round-trip decimal of a finite double, in msgspec's format; returns length */
int format_double(double value, char *out, size_t cap);
/* Python's float(f"{value:.9g}") */
double round_significant9(double value);
#endif
