/* A small JSON DOM for the tests (malloc is fine here: not the robot's control loop). */
#ifndef JDOM_H
#define JDOM_H
#include <stddef.h>
#include <stdint.h>

enum { J_NULL, J_BOOL, J_NUM, J_STR, J_ARR, J_OBJ };

typedef struct JNode {
    double num;
    long long integer;
    char *str; /* strings: UTF-8; numbers: their text */
    size_t str_len;
    struct JNode **items; /* arrays and objects' values */
    char **keys;          /* objects */
    size_t count;
    int type;
    int boolean;
    int is_int;
} JNode;

JNode *jdom_parse_file(const char *path);
/* Frees every DOM read so far (their nodes are gone): the runner calls it after each group
   of tests, so that a board holds one group's vectors at a time. */
void jdom_release(void);
JNode *jdom_get(const JNode *obj, const char *key); /* NULL if absent */
const char *jdom_str(const JNode *obj, const char *key);
size_t jdom_hex(const char *hex, unsigned char *out, size_t cap); /* bytes written */
#endif
