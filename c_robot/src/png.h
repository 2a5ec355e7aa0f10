/* PNG camera frames -> BGR pixels (8-bit greyscale, truecolour or truecolour with alpha,
   not interlaced: what OpenCV writes for the world's frames). */
#ifndef CR_PNG_H
#define CR_PNG_H
#include <stddef.h>
#include <stdint.h>

#include "limits.h"


typedef struct {
    int width, height;
    uint8_t *bgr; /* height * width * 3, row-major */
} Image;

/* 0 and the image (in a static buffer, valid until the next call), or -1 and why */
int png_decode(const uint8_t *data, size_t size, Image *image, const char **why);
#endif
