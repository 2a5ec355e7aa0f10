/* The C robot's unit tests: every conformance vector of tests/vectors/ that concerns a
   robot, read at test time (usage: unit-tests VECTOR_DIR). Prints "N passed, N failed".
   The key-file cases run the c-robot program next to this one (the folder of argv[0]),
   through the command prefix in C_ROBOT_EMULATOR if it is set (a cross build under
   qemu-user; c_robot/Makefile). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "jdom.h"
#include "tests.h"

int passed, failed;
const char *vector_dir;
char program_dir[1024];

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

static JNode *cases_root; /* read again after each group's release */

JNode *cases_json(void) {
    if (cases_root == NULL) cases_root = jdom_parse_file("tests/cases.json");
    return cases_root;
}

int main(int argc, char **argv) {
    vector_dir = argc > 1 ? argv[1] : "../tests/vectors";
    const char *slash = strrchr(argv[0], '/');
    if (slash == NULL) {
        strcpy(program_dir, ".");
    } else if ((size_t)(slash - argv[0]) < sizeof program_dir) {
        memcpy(program_dir, argv[0], (size_t)(slash - argv[0]));
        program_dir[slash - argv[0]] = '\0';
    } else {
        printf("FAIL the program's folder is longer than %zu bytes\n", sizeof program_dir - 1);
        return 1;
    }
    struct {
        const char *name;
        void (*fn)(void);
    } groups[] = {
        {"numeric", test_numeric},   {"rng", test_rng},           {"fsum", test_fsum},
        {"format", test_format},     {"auth", test_auth},         {"link", test_link},
        {"key files", test_key_files},
        {"messages", test_messages}, {"png+vision", test_png},
        {"decision", test_decision}, {"client", test_client},
        {"platform", test_platform},
        {"controller", test_controller_vectors},
    };
    for (size_t i = 0; i < sizeof groups / sizeof groups[0]; i++) {
        int before_p = passed, before_f = failed;
        groups[i].fn();
        jdom_release();
        cases_root = NULL;
        printf("%-10s %4d passed, %d failed\n", groups[i].name, passed - before_p,
               failed - before_f);
    }
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
