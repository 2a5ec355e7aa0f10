/* Go-to-goal with obstacle avoidance (robot_agent/core/navigation.py). */
#ifndef CR_NAVIGATION_H
#define CR_NAVIGATION_H
#include "limits.h"
#include "rng.h"

#define NAV_SENSORS 8

typedef struct {
    double max_speed, wheel_base, robot_radius, control_period;
    double turn_gain, min_turn_rate, slow_radius, min_speed, detect_level, clearance_level,
        clearance_gain, front_half_angle;
    int forget_steps;
    double obstacle_memory, stuck_time, stuck_distance, escape_time;
    int push_after;
    double prox_angles[NAV_SENSORS];
} NavParams;

typedef struct {
    NavParams params;
    Stream rng;
    double cos_[NAV_SENSORS], sin_[NAV_SENSORS];
    int front[NAV_SENSORS], front_count;
    int stuck_window, escape_steps_total;
    int has_goal;
    double goal_x, goal_y;
    double trail_x[NAV_MAX_TRAIL], trail_y[NAV_MAX_TRAIL];
    int trail_start, trail_len, trail_cap;
    int avoid_side;
    double obstacle_x, obstacle_y;
    int steps_clear, escape_steps;
    double escape_heading;
    int has_origin;
    double origin_x, origin_y;
    int fruitless_escapes, pushing;
    long escapes, pushes;
} Navigator;

/* 0, or -1 and why when the parameters are refused (NavParams.__post_init__) */
int nav_params_default(NavParams *p, double max_speed, double wheel_base, double robot_radius,
                       double control_period, const char **why);
int navigator_init(Navigator *n, const NavParams *params, Stream rng, const char **why);
void navigator_reset(Navigator *n);
/* returns 1 when arrived (wheels 0) */
int navigator_drive_to(Navigator *n, double x, double y, double theta, const double *proximity,
                       double goal_x, double goal_y, double tolerance, double *left,
                       double *right);
int navigator_turn_to(Navigator *n, double theta, double heading, double tolerance,
                      double *left, double *right);
#endif
