#include "jdom.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    const char *p, *e;
} P;

static void ws(P *p) {
    while (p->p < p->e && (*p->p == ' ' || *p->p == '\n' || *p->p == '\t' || *p->p == '\r')) p->p++;
}

static JNode *node(int type) {
    JNode *n = calloc(1, sizeof *n);
    n->type = type;
    return n;
}

static void push(JNode *n, JNode *item, char *key) {
    n->items = realloc(n->items, (n->count + 1) * sizeof *n->items);
    n->keys = realloc(n->keys, (n->count + 1) * sizeof *n->keys);
    n->items[n->count] = item;
    n->keys[n->count] = key;
    n->count++;
}

static char *string(P *p, size_t *len) {
    p->p++; /* " */
    size_t cap = 16, n = 0;
    char *s = malloc(cap);
    while (p->p < p->e && *p->p != '"') {
        unsigned cp;
        if (*p->p == '\\') {
            char k = p->p[1];
            p->p += 2;
            if (k == 'u') {
                sscanf(p->p, "%4x", &cp);
                p->p += 4;
                if (cp >= 0xD800 && cp <= 0xDBFF && p->p[0] == '\\' && p->p[1] == 'u') {
                    unsigned low;
                    sscanf(p->p + 2, "%4x", &low);
                    p->p += 6;
                    cp = 0x10000 + ((cp - 0xD800) << 10) + (low - 0xDC00);
                }
            } else {
                cp = k == 'n' ? '\n' : k == 't' ? '\t' : k == 'r' ? '\r' : k == 'b' ? '\b' : k == 'f' ? '\f' : (unsigned)k;
            }
            unsigned char tmp[4];
            int m;
            if (cp < 0x80) { tmp[0] = (unsigned char)cp; m = 1; }
            else if (cp < 0x800) { tmp[0] = (unsigned char)(0xC0 | cp >> 6); tmp[1] = (unsigned char)(0x80 | (cp & 63)); m = 2; }
            else if (cp < 0x10000) { tmp[0] = (unsigned char)(0xE0 | cp >> 12); tmp[1] = (unsigned char)(0x80 | ((cp >> 6) & 63)); tmp[2] = (unsigned char)(0x80 | (cp & 63)); m = 3; }
            else { tmp[0] = (unsigned char)(0xF0 | cp >> 18); tmp[1] = (unsigned char)(0x80 | ((cp >> 12) & 63)); tmp[2] = (unsigned char)(0x80 | ((cp >> 6) & 63)); tmp[3] = (unsigned char)(0x80 | (cp & 63)); m = 4; }
            for (int i = 0; i < m; i++) {
                if (n + 2 > cap) s = realloc(s, cap *= 2);
                s[n++] = (char)tmp[i];
            }
            continue;
        }
        if (n + 2 > cap) s = realloc(s, cap *= 2);
        s[n++] = *p->p++;
    }
    p->p++;
    s[n] = 0;
    *len = n;
    return s;
}

static JNode *value(P *p) {
    ws(p);
    char c = *p->p;
    if (c == '{') {
        JNode *n = node(J_OBJ);
        p->p++;
        ws(p);
        if (*p->p == '}') { p->p++; return n; }
        while (1) {
            ws(p);
            size_t len;
            char *key = string(p, &len);
            ws(p);
            p->p++; /* : */
            push(n, value(p), key);
            ws(p);
            if (*p->p++ == '}') return n;
        }
    }
    if (c == '[') {
        JNode *n = node(J_ARR);
        p->p++;
        ws(p);
        if (*p->p == ']') { p->p++; return n; }
        while (1) {
            push(n, value(p), NULL);
            ws(p);
            if (*p->p++ == ']') return n;
        }
    }
    if (c == '"') {
        JNode *n = node(J_STR);
        n->str = string(p, &n->str_len);
        return n;
    }
    if (!strncmp(p->p, "true", 4)) { p->p += 4; JNode *n = node(J_BOOL); n->boolean = 1; return n; }
    if (!strncmp(p->p, "false", 5)) { p->p += 5; return node(J_BOOL); }
    if (!strncmp(p->p, "null", 4)) { p->p += 4; return node(J_NULL); }
    JNode *n = node(J_NUM);
    const char *start = p->p;
    n->is_int = 1;
    while (p->p < p->e && strchr("+-0123456789.eE", *p->p)) {
        if (strchr(".eE", *p->p)) n->is_int = 0;
        p->p++;
    }
    n->str_len = (size_t)(p->p - start);
    n->str = malloc(n->str_len + 1);
    memcpy(n->str, start, n->str_len);
    n->str[n->str_len] = 0;
    n->num = strtod(n->str, NULL);
    n->integer = strtoll(n->str, NULL, 10);
    return n;
}

JNode *jdom_parse_file(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *text = malloc((size_t)size + 1);
    if (fread(text, 1, (size_t)size, f) != (size_t)size) { fclose(f); return NULL; }
    fclose(f);
    text[size] = 0;
    P p = {text, text + size};
    return value(&p);
}

JNode *jdom_get(const JNode *obj, const char *key) {
    if (!obj || obj->type != J_OBJ) return NULL;
    for (size_t i = 0; i < obj->count; i++)
        if (!strcmp(obj->keys[i], key)) return obj->items[i];
    return NULL;
}

const char *jdom_str(const JNode *obj, const char *key) {
    JNode *n = jdom_get(obj, key);
    return n && n->type == J_STR ? n->str : NULL;
}

size_t jdom_hex(const char *hex, unsigned char *out, size_t cap) {
    size_t n = 0;
    for (size_t i = 0; hex[i] && hex[i + 1] && n < cap; i += 2) {
        unsigned v;
        sscanf(hex + i, "%2x", &v);
        out[n++] = (unsigned char)v;
    }
    return n;
}
