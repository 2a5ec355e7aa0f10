#include "vision.h"

#include <string.h>

#define CHROMA_LIMIT 1080 /* 18 x 60: the neighbourhood's (R + B)/2 - G above 60 */
#define MIN_REGION_PIXELS 12
#define MIN_HEIGHT_FRACTION 0.3

/* a pixel's flags: in the chroma mask, and kept by the erosion */
#define MASKED 1
#define KEPT 2
static uint8_t flags[MAX_FRAME_PIXELS];
/* component labels and the flood's stack of pixel indices: 16 bits for frames of up to
   65535 pixels (a microcontroller's), 32 for larger */
#if MAX_FRAME_PIXELS <= 65535
typedef uint16_t Label;
#else
typedef int32_t Label;
#endif
static Label labels[MAX_FRAME_PIXELS];
static Label stack[MAX_FRAME_PIXELS];

/* BORDER_REFLECT_101: -1 -> 1, n -> n - 2 */
static int reflect(int i, int n) {
    if (i < 0) return n > 1 ? 1 : 0;
    if (i >= n) return n > 1 ? n - 2 : 0;
    return i;
}

int estimate_quality(const Image *image, double *quality) {
    int w = image->width, h = image->height;
    const uint8_t *px = image->bgr;
    if (w < 3 || h < 3) return 0; /* Python raises ValueError: no view of the site */
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            long sum[3] = {0, 0, 0};
            for (int dy = -1; dy <= 1; dy++) {
                int yy = reflect(y + dy, h);
                for (int dx = -1; dx <= 1; dx++) {
                    const uint8_t *p = px + ((size_t)yy * w + (size_t)reflect(x + dx, w)) * 3;
                    sum[0] += p[0];
                    sum[1] += p[1];
                    sum[2] += p[2];
                }
            }
            flags[y * w + x] = (sum[2] + sum[0] - 2 * sum[1]) > CHROMA_LIMIT ? MASKED : 0;
        }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int keep = 1;
            for (int dy = -1; dy <= 1 && keep; dy++)
                for (int dx = -1; dx <= 1; dx++) {
                    int yy = y + dy, xx = x + dx;
                    if (yy < 0 || yy >= h || xx < 0 || xx >= w || !(flags[yy * w + xx] & MASKED)) {
                        keep = 0;
                        break;
                    }
                }
            if (keep) flags[y * w + x] |= KEPT;
        }
    /* 4-connected components, found in row-major order: each one's first pixel is where
       its flood starts. The facing one: inside the central band, tall and large enough,
       nearest the centre (dx, then dy, then first pixel). */
    memset(labels, 0, sizeof(Label) * (size_t)w * (size_t)h);
    double centre_x = w / 2.0, centre_y = h / 2.0;
    double band_left = w / 4.0, band_right = 3.0 * w / 4.0;
    int best = 0, label = 0;
    double best_dx = 0, best_dy = 0;
    long best_first = 0;
    for (int start = 0; start < w * h; start++) {
        if (!(flags[start] & KEPT) || labels[start]) continue;
        label++; /* at most one a kept pixel: it fits a Label */
        int top = h, left = w, bottom = -1, right = -1;
        long area = 0;
        int sp = 0;
        stack[sp++] = (Label)start;
        labels[start] = (Label)label;
        while (sp) {
            int p = stack[--sp];
            int y = p / w, x = p % w;
            area++;
            if (x < left) left = x;
            if (x > right) right = x;
            if (y < top) top = y;
            if (y > bottom) bottom = y;
            int next[4] = {y > 0 ? p - w : -1, y < h - 1 ? p + w : -1, x > 0 ? p - 1 : -1,
                           x < w - 1 ? p + 1 : -1};
            for (int k = 0; k < 4; k++) {
                int q = next[k];
                if (q >= 0 && (flags[q] & KEPT) && !labels[q]) {
                    labels[q] = (Label)label;
                    stack[sp++] = (Label)q;
                }
            }
        }
        int region_width = right - left + 1, region_height = bottom - top + 1;
        int region_right = left + region_width, region_bottom = top + region_height;
        if (area < MIN_REGION_PIXELS || region_height < MIN_HEIGHT_FRACTION * h) continue;
        if (region_right <= band_left || left >= band_right) continue;
        double dx = left - centre_x;
        if (centre_x - region_right > dx) dx = centre_x - region_right;
        if (0.0 > dx) dx = 0.0;
        double dy = top - centre_y;
        if (centre_y - region_bottom > dy) dy = centre_y - region_bottom;
        if (0.0 > dy) dy = 0.0;
        if (!best || dx < best_dx || (dx == best_dx && (dy < best_dy ||
                                                         (dy == best_dy && start < best_first)))) {
            best = label;
            best_dx = dx;
            best_dy = dy;
            best_first = start;
        }
    }
    if (!best) return 0;
    long long red = 0, blue = 0;
    for (int p = 0; p < w * h; p++)
        if (labels[p] == best) {
            red += px[(size_t)p * 3 + 2];
            blue += px[(size_t)p * 3];
        }
    if (red + blue == 0) return 0;
    *quality = (double)red / (double)(red + blue);
    return 1;
}
