#include "motor_guard.h"

void motor_guard_init(MotorGuard *g, double timeout) {
    g->timeout = timeout;
    g->has_command = 0;
    g->left = g->right = g->at = 0.0;
    g->stops = 0;
    g->stopped = 1;
}

void motor_guard_command(MotorGuard *g, double now, double left, double right) {
    g->has_command = 1;
    g->left = left;
    g->right = right;
    g->at = now;
}

void motor_guard_wheels(MotorGuard *g, double now, double *left, double *right) {
    int live = g->has_command && now - g->at < g->timeout;
    if (!live && g->has_command && !g->stopped && (g->left != 0.0 || g->right != 0.0))
        g->stops++;
    g->stopped = !live || (g->left == 0.0 && g->right == 0.0);
    *left = live ? g->left : 0.0;
    *right = live ? g->right : 0.0;
}
