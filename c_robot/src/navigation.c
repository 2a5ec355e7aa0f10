#include "navigation.h"

#include <math.h>
#include <string.h>

#include "numeric.h"

static const double EPUCK_PROX_ANGLES[NAV_SENSORS] = {-0.30, -0.80, -1.57, -2.64,
                                                       2.64,  1.57,  0.80,  0.30};

int nav_params_default(NavParams *p, double max_speed, double wheel_base, double robot_radius,
                       double control_period, const char **why) {
    p->max_speed = max_speed;
    p->wheel_base = wheel_base;
    p->robot_radius = robot_radius;
    p->control_period = control_period;
    p->turn_gain = 4.0;
    p->min_turn_rate = 0.4;
    p->slow_radius = 0.08;
    p->min_speed = 0.015;
    p->detect_level = 0.05;
    p->clearance_level = 0.35;
    p->clearance_gain = 1.6;
    p->front_half_angle = 0.9;
    p->forget_steps = 15;
    p->obstacle_memory = 0.6;
    p->stuck_time = 3.0;
    p->stuck_distance = 0.02;
    p->escape_time = 1.5;
    p->push_after = 3;
    memcpy(p->prox_angles, EPUCK_PROX_ANGLES, sizeof EPUCK_PROX_ANGLES);
    if (!(isfinite(max_speed) && max_speed > 0 && isfinite(wheel_base) && wheel_base > 0 &&
          isfinite(robot_radius) && robot_radius > 0 && isfinite(control_period) &&
          control_period > 0)) {
        *why = "NavParams: the body's figures must be positive numbers";
        return -1;
    }
    if (!(0.0 <= p->min_turn_rate && p->min_turn_rate <= 2 * p->max_speed / p->wheel_base)) {
        *why = "NavParams.min_turn_rate must be in [0, 2 max_speed / wheel_base]";
        return -1;
    }
    if (!(0.0 <= p->min_speed && p->min_speed <= p->max_speed)) {
        *why = "NavParams.min_speed must be in [0, max_speed]";
        return -1;
    }
    return 0;
}

static int round_int(double x) { return (int)nk_round_half_even(x); }

int navigator_init(Navigator *n, const NavParams *params, Stream rng, const char **why) {
    memset(n, 0, sizeof *n);
    n->params = *params;
    n->rng = rng;
    n->front_count = 0;
    for (int i = 0; i < NAV_SENSORS; i++) {
        nk_sincos(params->prox_angles[i], &n->sin_[i], &n->cos_[i]);
        if (fabs(nk_wrap_angle(params->prox_angles[i])) <= params->front_half_angle)
            n->front[n->front_count++] = i;
    }
    int window = round_int(params->stuck_time / params->control_period);
    n->stuck_window = window > 2 ? window : 2;
    int steps = round_int(params->escape_time / params->control_period);
    n->escape_steps_total = steps > 1 ? steps : 1;
    n->trail_cap = n->stuck_window + 1;
    if (n->trail_cap > NAV_MAX_TRAIL) {
        *why = "the control period is too short for the navigator's trail";
        return -1;
    }
    navigator_reset(n);
    return 0;
}

void navigator_reset(Navigator *n) {
    n->has_goal = 0;
    n->trail_start = n->trail_len = 0;
    n->avoid_side = 0;
    n->obstacle_x = n->obstacle_y = 0.0;
    n->steps_clear = 0;
    n->escape_steps = 0;
    n->has_origin = 0;
    n->fruitless_escapes = 0;
    n->pushing = 0;
}

static void trail_append(Navigator *n, double x, double y) {
    if (n->trail_len == n->trail_cap) { /* a deque with maxlen: the oldest goes */
        n->trail_start = (n->trail_start + 1) % n->trail_cap;
        n->trail_len--;
    }
    int at = (n->trail_start + n->trail_len) % n->trail_cap;
    n->trail_x[at] = x;
    n->trail_y[at] = y;
    n->trail_len++;
}

static int choice_sign(Stream *rng) { return stream_randrange(rng, 2) == 0 ? -1 : 1; }

static double steer(Navigator *n, double bearing, const double *proximity, double theta) {
    const NavParams *p = &n->params;
    double nearest = proximity[0];
    for (int i = 1; i < NAV_SENSORS; i++)
        if (proximity[i] > nearest) nearest = proximity[i];
    if (nearest <= p->detect_level) {
        n->obstacle_x = n->obstacle_y = 0.0;
        n->steps_clear += 1;
        if (n->steps_clear >= p->forget_steps) n->avoid_side = 0;
        return bearing;
    }
    n->steps_clear = 0;
    double ahead = 0.0, left = 0.0;
    for (int i = 0; i < NAV_SENSORS; i++) {
        ahead += proximity[i] * n->cos_[i];
        left += proximity[i] * n->sin_[i];
    }
    double sin_theta, cos_theta;
    nk_sincos(theta, &sin_theta, &cos_theta);
    double memory = p->obstacle_memory;
    double ox = memory * n->obstacle_x + (1 - memory) * (ahead * cos_theta - left * sin_theta);
    double oy = memory * n->obstacle_y + (1 - memory) * (ahead * sin_theta + left * cos_theta);
    n->obstacle_x = ox;
    n->obstacle_y = oy;
    if (ox == 0.0 && oy == 0.0) return bearing;
    double obstacle = nk_wrap_angle(nk_atan2(oy, ox) - theta);
    double goal_vs_obstacle = nk_wrap_angle(bearing - obstacle);
    if (fabs(goal_vs_obstacle) >= NK_PI / 2) return bearing;
    if (n->avoid_side == 0) {
        if (fabs(goal_vs_obstacle) > 0.15)
            n->avoid_side = goal_vs_obstacle > 0 ? 1 : -1;
        else
            n->avoid_side = choice_sign(&n->rng);
    }
    double push = p->clearance_gain * (nearest - p->clearance_level);
    double low = -NK_PI / 4, high = NK_PI / 2;
    push = low > push ? low : push;
    push = high < push ? high : push;
    return nk_wrap_angle(obstacle + (double)n->avoid_side * (NK_PI / 2 + push));
}

static double front_reading(const Navigator *n, const double *proximity) {
    double nearest = 0.0;
    int first = 1;
    for (int k = 0; k < n->front_count; k++) {
        double reading = proximity[n->front[k]];
        if (first || reading > nearest) {
            nearest = reading;
            first = 0;
        }
    }
    return nearest;
}

static double turn_rate(const Navigator *n, double error) {
    const NavParams *p = &n->params;
    double size = fabs(error);
    double rate = p->turn_gain * size;
    rate = p->min_turn_rate > rate ? p->min_turn_rate : rate;
    double settle = size / p->control_period;
    rate = settle < rate ? settle : rate;
    double max_turn = 2.0 * p->max_speed / p->wheel_base;
    rate = max_turn < rate ? max_turn : rate;
    return copysign(rate, error);
}

static void wheels(const Navigator *n, double forward, double rate, double *left, double *right) {
    double limit = n->params.max_speed;
    double spin = rate * n->params.wheel_base / 2.0;
    spin = -limit > spin ? -limit : spin;
    spin = limit < spin ? limit : spin;
    forward = forward < 0.0 ? 0.0 : forward;
    double room = limit - fabs(spin);
    forward = room < forward ? room : forward;
    *left = forward - spin;
    *right = forward + spin;
}

static int is_stuck(const Navigator *n, double x, double y) {
    if (n->trail_len < n->stuck_window) return 0;
    double old_x = n->trail_x[n->trail_start], old_y = n->trail_y[n->trail_start];
    return nk_hypot(x - old_x, y - old_y) < n->params.stuck_distance;
}

static void start_escape(Navigator *n, double x, double y, double theta, double goal_heading) {
    if (n->has_origin && nk_hypot(x - n->origin_x, y - n->origin_y) < n->params.robot_radius) {
        n->fruitless_escapes += 1;
    } else {
        n->has_origin = 1;
        n->origin_x = x;
        n->origin_y = y;
        n->fruitless_escapes = 0;
    }
    n->pushing = n->fruitless_escapes >= n->params.push_after;
    if (n->pushing) {
        n->escape_heading = goal_heading;
        n->pushes += 1;
    } else {
        double turn = stream_uniform(&n->rng, NK_PI / 2, NK_PI);
        turn = turn * (double)choice_sign(&n->rng);
        n->escape_heading = nk_wrap_angle(theta + turn);
        n->avoid_side = choice_sign(&n->rng);
    }
    n->escape_steps = n->escape_steps_total;
    n->trail_start = n->trail_len = 0;
    n->escapes += 1;
}

int navigator_drive_to(Navigator *n, double x, double y, double theta, const double *proximity,
                       double goal_x, double goal_y, double tolerance, double *left,
                       double *right) {
    const NavParams *p = &n->params;
    if (!n->has_goal || goal_x != n->goal_x || goal_y != n->goal_y) {
        navigator_reset(n);
        n->has_goal = 1;
        n->goal_x = goal_x;
        n->goal_y = goal_y;
    }
    double dx = goal_x - x, dy = goal_y - y;
    double distance = sqrt(dx * dx + dy * dy);
    if (distance <= tolerance) {
        n->trail_start = n->trail_len = 0;
        n->escape_steps = 0;
        *left = *right = 0.0;
        return 1;
    }
    double bearing;
    if (n->escape_steps > 0) {
        n->escape_steps -= 1;
        bearing = nk_wrap_angle(n->escape_heading - theta);
    } else {
        n->pushing = 0;
        bearing = nk_wrap_angle(nk_atan2(dy, dx) - theta);
        if (is_stuck(n, x, y)) {
            start_escape(n, x, y, theta, nk_atan2(dy, dx));
            bearing = nk_wrap_angle(n->escape_heading - theta);
        }
    }
    trail_append(n, x, y);
    double heading_error = n->pushing ? bearing : steer(n, bearing, proximity, theta);
    double ratio = distance / p->slow_radius;
    double cap = p->max_speed * (ratio < 1.0 ? ratio : 1.0);
    cap = p->min_speed > cap ? p->min_speed : cap;
    double reach = distance / p->control_period;
    cap = reach < cap ? reach : cap;
    double facing = (-1.58 < heading_error && heading_error < 1.58) ? nk_cos(heading_error) : 0.0;
    double forward = cap * (facing > 0.0 ? facing : 0.0);
    if (!n->pushing) forward *= 1.0 - front_reading(n, proximity);
    wheels(n, forward, turn_rate(n, heading_error), left, right);
    return 0;
}

int navigator_turn_to(Navigator *n, double theta, double heading, double tolerance,
                      double *left, double *right) {
    double error = nk_wrap_angle(heading - theta);
    if (fabs(error) <= tolerance) {
        *left = *right = 0.0;
        return 1;
    }
    wheels(n, 0.0, turn_rate(n, error), left, right);
    return 0;
}
