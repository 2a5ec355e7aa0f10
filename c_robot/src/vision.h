/* The quality estimator of docs/camera.md (robot_agent/core/vision.py), in integers. */
#ifndef CR_VISION_H
#define CR_VISION_H
#include "png.h"

/* 1 and the quality, or 0: no site in view (None) */
int estimate_quality(const Image *image, double *quality);
#endif
