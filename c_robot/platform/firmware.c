/* The robot as firmware: c_robot/src/ on a serial line, bare metal (board.h), the Linux
   program's loop (src/main.c serve) without an operating system.

It reads its id, run and key from the key record in flash, says hello on the link's UART
until the run's bridge welcomes it, asks the world for its map and from then on steps
once a tick's inputs are in, each step's command held by the motor guard. When the bridge
says the run has ended it writes the program's last line to the log, and a line of its
own figures, and halts. Nothing ends it otherwise: a silent bridge, a BYE 2 or 3, lead to
hellos until a bridge answers. */
#include <stdio.h>
#include <string.h>

#include "board.h"
#include "client.h"
#include "json.h"
#include "key_record.h"
#include "keyfile.h"
#include "link.h"
#include "log.h"
#include "motor_guard.h"

/* a command holds this many control periods at most (the map's dt; before it, none) */
#define MOTOR_PERIODS 3

static LinkRobot program;
static Deframer deframer;
static MotorGuard guard;
static long framing_refused[R_COUNT]; /* the serial framing's refusals (corrupt, oversize) */
static size_t largest_frame; /* the longest link frame received (a camera frame's PNG in it) */

/* what the steps cost, in clock ticks (under qemu -icount, instructions: docs/porting.md):
   a step as the firmware takes it (from the tick's last input to the act sealed: the
   input's tag, the PNG, the controller, the messages and their tags), and the controller's
   step alone */
typedef struct {
    int64_t count;
    uint64_t total, worst, began;
} Cost;
static Cost cost, controller_cost;

static void spend(Cost *c, uint64_t spent) {
    c->count++;
    c->total += spent;
    if (spent > c->worst) c->worst = spent;
}

void step_probe(int begin) {
    uint64_t now = board_clock();
    if (begin) controller_cost.began = now;
    else spend(&controller_cost, now - controller_cost.began);
}

static double seconds(uint64_t ticks) { return (double)ticks / (double)board_clock_hz; }

static void log_to_board(const char *line, size_t size) { board_log(line, size); }

static void emit(void *ctx, const uint8_t *bytes, size_t size) {
    (void)ctx;
    board_link_write(bytes, size);
}

static void send_outgoing(void) {
    size_t size;
    const uint8_t *frame;
    for (int i = 0; (frame = client_frame(&program.client, i, &size)) != NULL; i++)
        serial_encode_each(frame, size, emit, NULL);
    client_clear(&program.client);
}

static void on_frame(void *ctx, uint8_t *frame, size_t size, int refusal) {
    double now = *(const double *)ctx;
    if (frame == NULL) {
        framing_refused[refusal]++;
        return;
    }
    if (size > largest_frame) largest_frame = size;
    int64_t before = program.has_endpoint ? program.endpoint->steps : 0;
    uint64_t start = board_clock();
    link_robot_receive(&program, frame, size, now);
    if (program.has_endpoint && program.endpoint->steps != before) { /* a step */
        spend(&cost, board_clock() - start);
        motor_guard_command(&guard, now, program.endpoint->left, program.endpoint->right);
    }
}

static void drive(double now) {
    double left, right;
    if (program.has_endpoint && guard.timeout == 0.0)
        guard.timeout = MOTOR_PERIODS * program.endpoint->dt;
    motor_guard_wheels(&guard, now, &left, &right);
    board_motors(left, right);
}

static void report(void) {
    static char line[1024];
    link_robot_summary(&program, line, sizeof line - 1);
    size_t n = strlen(line);
    line[n++] = '\n';
    board_log(line, n); /* the program's last line, as the Linux program prints it */
    long refused = 0;
    for (int i = 0; i < R_COUNT; i++) refused += framing_refused[i];
    char total[21], worst[21], controller_total[21], controller_worst[21];
    format_int((int64_t)cost.total, total); /* newlib-nano's printf has no %llu */
    format_int((int64_t)cost.worst, worst);
    format_int((int64_t)controller_cost.total, controller_total);
    format_int((int64_t)controller_cost.worst, controller_worst);
    n = (size_t)snprintf(line, sizeof line,
                         "{\"firmware\": {\"steps\": %ld, \"step_ticks_total\": %s, "
                         "\"step_ticks_worst\": %s, \"controller_ticks_total\": %s, "
                         "\"controller_ticks_worst\": %s, \"clock_hz\": %lu, "
                         "\"stack_peak\": %lu, \"heap_peak\": %lu, \"largest_frame\": %lu, "
                         "\"framing_refused\": %ld, \"overruns\": %lu, \"motor_stops\": %ld, "
                         "\"queue_dropped\": %ld}}\n",
                         (long)cost.count, total, worst, controller_total, controller_worst,
                         (unsigned long)board_clock_hz,
                         (unsigned long)board_stack_peak(), (unsigned long)board_heap_peak(),
                         (unsigned long)largest_frame, refused, (unsigned long)board_link_overruns(), guard.stops,
                         program.client.queue_dropped);
    board_log(line, n);
}

int main(void) {
    board_init();
    log_sink = log_to_board;
    motor_guard_init(&guard, 0.0);
    board_motors(0.0, 0.0);
    size_t available;
    const uint8_t *record = board_key_record(&available);
    int robot;
    const uint8_t *text;
    size_t size;
    const char *why;
    if (key_record_read(record, available, &robot, &text, &size, &why) != 0) {
        log_error("%s: cannot run", why);
        board_halt(2);
    }
    log_robot = robot;
    static char run[MAX_NAME + 1];
    uint8_t key[32];
    int found = key_file_read(text, size, robot, run, key, &why);
    if (found != KEY_FILE_OK) {
        log_error("the key record's key file: %s%s",
                  found == KEY_FILE_NO_KEY ? "it holds no key for this robot" : why, "");
        board_halt(2);
    }
    if (link_robot_init(&program, robot, run, key) != 0) {
        log_error("robot %d: no source of random bytes for the link's nonces: cannot run",
                  robot);
        board_halt(1);
    }
    memset(key, 0, sizeof key);
    log_info("robot %d of run %s: saying hello on the link's UART", robot, run);
    while (!program.ended) {
        double now = seconds(board_clock());
        link_robot_wake(&program, now);
        send_outgoing();
        uint8_t chunk[256];
        size_t n;
        int heard = 0;
        while ((n = board_link_read(chunk, sizeof chunk)) > 0) {
            now = seconds(board_clock());
            deframer_feed(&deframer, chunk, n, on_frame, &now);
            send_outgoing(); /* answer at once */
            heard = 1;
        }
        if (heard && deframer_receiving(&deframer))
            link_robot_hearing(&program, now); /* a long frame under way is not silence */
        drive(now);
        if (!heard) board_idle(); /* until a byte comes or the clock ticks */
    }
    link_robot_stop(&program); /* nothing more to say after a BYE 1; a BYE 2 otherwise */
    send_outgoing();
    board_motors(0.0, 0.0);
    report();
    board_halt(program.fatal ? 1 : 0);
}
