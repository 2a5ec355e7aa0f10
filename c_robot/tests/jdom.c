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

/* What the DOM holds comes from blocks of ARENA_BLOCK bytes, freed all at once by
   jdom_release: no allocation overhead, so that the vectors fit a board's RAM (make
   test-m4). Each block starts with the one before it. */
#define ARENA_BLOCK (256 * 1024)
#define BLOCK_HEADER 8 /* the link to the block before, kept 8-byte aligned */
static char *arena_at, *arena_end, *last_block;

static void *arena(size_t size) {
    size = (size + 7) & ~(size_t)7;
    if (size > (size_t)(arena_end - arena_at)) {
        size_t block = size > ARENA_BLOCK ? size : ARENA_BLOCK;
        char *fresh = malloc(BLOCK_HEADER + block);
        if (fresh == NULL) {
            printf("FAIL the vectors do not fit in memory\n");
            exit(1);
        }
        memcpy(fresh, &last_block, sizeof last_block);
        last_block = fresh;
        arena_at = fresh + BLOCK_HEADER;
        arena_end = arena_at + block;
    }
    void *p = arena_at;
    arena_at += size;
    return p;
}

void jdom_release(void) {
    while (last_block != NULL) {
        char *before;
        memcpy(&before, last_block, sizeof before);
        free(last_block);
        last_block = before;
    }
    arena_at = arena_end = NULL;
}

static char *kept(const char *text, size_t size) {
    char *copy = arena(size + 1);
    memcpy(copy, text, size);
    copy[size] = 0;
    return copy;
}

static JNode *node(int type) {
    JNode *n = arena(sizeof *n);
    memset(n, 0, sizeof *n);
    n->type = type;
    return n;
}

/* an array's or an object's members, gathered in a growing list, kept at their end */
typedef struct {
    JNode **items;
    char **keys;
    size_t count, cap;
} Members;

static void push(Members *m, JNode *item, char *key) {
    if (m->count == m->cap) {
        m->cap = m->cap ? 2 * m->cap : 8;
        m->items = realloc(m->items, m->cap * sizeof *m->items);
        m->keys = realloc(m->keys, m->cap * sizeof *m->keys);
    }
    m->items[m->count] = item;
    m->keys[m->count] = key;
    m->count++;
}

static JNode *keep(JNode *n, Members *m) {
    n->count = m->count;
    n->items = arena(m->count * sizeof *n->items);
    memcpy(n->items, m->items, m->count * sizeof *n->items);
    if (n->type == J_OBJ) {
        n->keys = arena(m->count * sizeof *n->keys);
        memcpy(n->keys, m->keys, m->count * sizeof *n->keys);
    }
    free(m->items);
    free(m->keys);
    return n;
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
    *len = n;
    char *copy = kept(s, n);
    free(s);
    return copy;
}

static JNode *value(P *p) {
    ws(p);
    char c = *p->p;
    if (c == '{') {
        JNode *n = node(J_OBJ);
        Members m = {NULL, NULL, 0, 0};
        p->p++;
        ws(p);
        if (*p->p == '}') { p->p++; return keep(n, &m); }
        while (1) {
            ws(p);
            size_t len;
            char *key = string(p, &len);
            ws(p);
            p->p++; /* : */
            push(&m, value(p), key);
            ws(p);
            if (*p->p++ == '}') return keep(n, &m);
        }
    }
    if (c == '[') {
        JNode *n = node(J_ARR);
        Members m = {NULL, NULL, 0, 0};
        p->p++;
        ws(p);
        if (*p->p == ']') { p->p++; return keep(n, &m); }
        while (1) {
            push(&m, value(p), NULL);
            ws(p);
            if (*p->p++ == ']') return keep(n, &m);
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
    n->str = kept(start, n->str_len);
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
    JNode *root = value(&p);
    free(text);
    return root;
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
