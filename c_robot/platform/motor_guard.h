/* The motor time-out (docs/porting.md): a command holds until the next step, one control
   period later; when none has come for `timeout` seconds (the control loop stalled, the
   link gone, the world not ticking), the wheels stop rather than drive on. Pure: the time
   is given. */
#ifndef CR_MOTOR_GUARD_H
#define CR_MOTOR_GUARD_H

typedef struct {
    double timeout;
    int has_command;
    double left, right, at;
    long stops; /* times the guard stopped wheels that were turning */
    int stopped;
} MotorGuard;

void motor_guard_init(MotorGuard *g, double timeout);
/* the step's command, at now */
void motor_guard_command(MotorGuard *g, double now, double left, double right);
/* what the wheels do at now: the last command within the timeout, else 0, 0 */
void motor_guard_wheels(MotorGuard *g, double now, double *left, double *right);
#endif
