#ifndef TESTS_H
#define TESTS_H
#include "jdom.h"
extern int passed, failed;
/* The folder of the unit-tests program; the build puts c-robot in the same folder. */
extern char program_dir[];
void check(int ok, const char *what, const char *name);
JNode *load(const char *file);
/* tests/cases.json, read once for every group that uses it */
JNode *cases_json(void);
void test_numeric(void);
void test_rng(void);
void test_fsum(void);
void test_format(void);
void test_auth(void);
void test_link(void);
void test_key_files(void);
void test_messages(void);
void test_png(void);
void test_decision(void);
void test_client(void);
void test_platform(void);
void test_controller_vectors(void);
#endif
