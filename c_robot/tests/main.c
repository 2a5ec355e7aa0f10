/* The C robot's unit tests: every conformance vector of tests/vectors/ that concerns a
   robot, read at test time (usage: unit-tests VECTOR_DIR). Prints "N passed, N failed". */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "jdom.h"
#include "tests.h"

int passed, failed;
const char *vector_dir;

void check(int ok, const char *what, const char *name) {
    if (ok) {
        passed++;
    } else {
        failed++;
        printf("FAIL %s: %s\n", what, name);
    }
}

JNode *load(const char *file) {
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", vector_dir, file);
    JNode *n = jdom_parse_file(path);
    if (!n) {
        printf("FAIL cannot read %s\n", path);
        failed++;
    }
    return n;
}

int main(int argc, char **argv) {
    vector_dir = argc > 1 ? argv[1] : "../tests/vectors";
    struct {
        const char *name;
        void (*fn)(void);
    } groups[] = {
        {"numeric", test_numeric},   {"rng", test_rng},           {"fsum", test_fsum},
        {"format", test_format},     {"auth", test_auth},         {"link", test_link},
        {"key files", test_key_files},
        {"messages", test_messages}, {"png+vision", test_png},
        {"decision", test_decision}, {"client", test_client},
    };
    for (size_t i = 0; i < sizeof groups / sizeof groups[0]; i++) {
        int before_p = passed, before_f = failed;
        groups[i].fn();
        printf("%-10s %4d passed, %d failed\n", groups[i].name, passed - before_p,
               failed - before_f);
    }
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
