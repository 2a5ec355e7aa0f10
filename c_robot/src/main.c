/* c-robot: one robot of a run outside the emulator, in C99 (robot-agent --link's twin).

    c-robot --link udp://127.0.0.1:47800 --id 8 --key-file robot-8.key
    c-robot --link serial:/dev/ttyUSB0@921600 --id 8 --key-file robot-8.key

It says hello until the run's bridge welcomes it, asks the world for its map
(world/info, relayed), builds its controller (its generator from the run's seed and its
id), sends its first status and from then on steps once a tick's inputs are in. When the
bridge says the run has ended it prints one JSON line and exits 0. */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netdb.h>
#include <stddef.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "auth.h"
#include "client.h"
#include "json.h"
#include "keyfile.h"
#include "link.h"
#include "log.h"

#define PROGRAM "c-robot"
#define MAX_WAIT 0.2
#define REOPEN_EVERY 1.0
#define DRAIN_WAIT 2.0
#define DEFAULT_BAUD 115200
#define MAX_PENDING_BYTES (256 * 1024)
#define MAX_DATAGRAMS_PER_RECEIVE 256
#define READ_BYTES 65536
/* the serial line's bytes are written as the line would carry them, in slices of this much
   line time (bestofn_swarm/link/core/pacing.py SLICE_SECONDS) */
#define SLICE_SECONDS 0.02

static const char USAGE[] =
    "usage: " PROGRAM " [-h] --link ADDRESS --id ID --key-file FILE [--give-up SECONDS]\n"
    "               [--log-level {debug,info,warning,error}]\n";

static void usage_error(const char *format, const char *a, const char *b) {
    fputs(USAGE, stderr);
    fprintf(stderr, PROGRAM ": error: ");
    fprintf(stderr, format, a, b);
    fputc('\n', stderr);
    exit(2);
}

static double now_monotonic(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* --- the link's address (bestofn_swarm/link/core/codec.py parse_address) --------------------------------- */

typedef struct {
    int udp;
    char host[256];
    char port[8];
    char path[1024];
    long baud;
} Address;

static int all_digits(const char *s) {
    if (!*s) return 0;
    for (; *s; s++)
        if (*s < '0' || *s > '9') return 0;
    return 1;
}

static int parse_address(const char *text, Address *a) {
    memset(a, 0, sizeof *a);
    if (!strncmp(text, "udp://", 6)) {
        const char *rest = text + 6;
        const char *colon = strrchr(rest, ':');
        if (!colon) return -1;
        size_t hn = (size_t)(colon - rest);
        const char *port = colon + 1;
        if (hn >= 2 && rest[0] == '[' && rest[hn - 1] == ']') {
            rest++;
            hn -= 2;
        }
        if (hn == 0 || hn >= sizeof a->host || !all_digits(port) || strlen(port) > 5 ||
            atol(port) > 65535)
            return -1;
        memcpy(a->host, rest, hn);
        snprintf(a->port, sizeof a->port, "%ld", atol(port));
        a->udp = 1;
        return 0;
    }
    if (!strncmp(text, "serial:", 7)) {
        const char *rest = text + 7;
        const char *at = strrchr(rest, '@');
        size_t pn;
        const char *baud;
        if (at) {
            pn = (size_t)(at - rest);
            baud = at + 1;
        } else {
            pn = strlen(rest);
            baud = "115200";
        }
        if (pn == 0 || pn >= sizeof a->path || !all_digits(baud) || strlen(baud) > 9) return -1;
        long b = atol(baud);
        if (b < 50 || b > 10000000) return -1;
        memcpy(a->path, rest, pn);
        a->baud = b;
        return 0;
    }
    return -1;
}

/* --- the key file (bestofn_swarm/wire/auth.py keyring_from_text; program.py read_key_file) ---------- */

static void key_file_error(const char *format, const char *a, const char *b) {
    fprintf(stderr, "robot-agent: error: ");
    fprintf(stderr, format, a, b);
    fputc('\n', stderr);
    exit(2);
}

static void read_key_file(const char *path, int robot, char *run, uint8_t key[32]) {
    static uint8_t text[KEY_FILE_BYTES];
    int fd = open(path, O_RDONLY);
    if (fd < 0) key_file_error("cannot read key file %s: %s", path, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) == 0 && (st.st_mode & 077))
        log_warning("key file %s can be read by other users (chmod 600 it)", path);
    ssize_t size = read(fd, text, sizeof text);
    close(fd);
    if (size < 0) key_file_error("cannot read key file %s: %s", path, strerror(errno));
    if ((size_t)size == sizeof text) key_file_error("%s: %s", path, "not JSON");
    const char *why;
    int found = key_file_read(text, (size_t)size, robot, run, key, &why);
    if (found == KEY_FILE_NO_KEY) {
        char robot_text[16];
        snprintf(robot_text, sizeof robot_text, "%d", robot);
        key_file_error("%s holds no key for robot %s", path, robot_text);
    }
    if (found != KEY_FILE_OK) key_file_error("%s: %s", path, why);
}

/* --- transports (bestofn_swarm/link/io/transport.py) -------------------------------------- */

typedef struct {
    int fd;
    int udp;
    /* serial: the pacer (bestofn_swarm/link/core/pacing.py PacedLine) and what waits to be written */
    double baud, free_at;
    size_t slice; /* bytes handed on at a time */
    uint8_t pending[MAX_PENDING_BYTES];
    size_t pending_used;
    /* the frames not yet handed on whole, in order: when their first and last bytes arrive */
    double start[OUT_QUEUE_FRAMES * 4], done[OUT_QUEUE_FRAMES * 4];
    size_t size[OUT_QUEUE_FRAMES * 4];
    int queued;
    size_t handed;    /* bytes of the first of them handed on */
    size_t unwritten; /* bytes at the front of pending handed on, not yet written */
    Deframer deframer;
    long refused[R_COUNT];
    long sent, send_failures;
} Transport;

static Transport transport;

static speed_t speed_of(long baud) {
    switch (baud) {
    case 50: return B50; case 75: return B75; case 110: return B110; case 134: return B134;
    case 150: return B150; case 200: return B200; case 300: return B300; case 600: return B600;
    case 1200: return B1200; case 1800: return B1800; case 2400: return B2400;
    case 4800: return B4800; case 9600: return B9600; case 19200: return B19200;
    case 38400: return B38400;
#ifdef B57600
    case 57600: return B57600;
#endif
#ifdef B115200
    case 115200: return B115200;
#endif
#ifdef B230400
    case 230400: return B230400;
#endif
#ifdef B460800
    case 460800: return B460800;
#endif
#ifdef B921600
    case 921600: return B921600;
#endif
    default: return B0;
    }
}

static int open_transport(const Address *a, Transport *t) {
    memset(t, 0, offsetof(Transport, pending));
    t->queued = 0;
    t->pending_used = 0;
    t->handed = 0;
    t->unwritten = 0;
    t->deframer.used = 0;
    t->deframer.overflowed = 0;
    if (a->udp) {
        struct addrinfo hints, *infos;
        memset(&hints, 0, sizeof hints);
        hints.ai_socktype = SOCK_DGRAM;
        int rc = getaddrinfo(a->host, a->port, &hints, &infos);
        if (rc != 0) {
            log_warning("cannot open the link udp://%s:%s: %s", a->host, a->port, gai_strerror(rc));
            return -1;
        }
        int fd = socket(infos->ai_family, SOCK_DGRAM, 0);
        if (fd < 0) {
            freeaddrinfo(infos);
            return -1;
        }
        int size = 1024 * 1024;
        setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &size, sizeof size);
        fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK);
        if (connect(fd, infos->ai_addr, infos->ai_addrlen) != 0) {
            log_warning("cannot open the link udp://%s:%s: %s", a->host, a->port, strerror(errno));
            freeaddrinfo(infos);
            close(fd);
            return -1;
        }
        freeaddrinfo(infos);
        t->fd = fd;
        t->udp = 1;
        return 0;
    }
    int fd = open(a->path, O_RDWR | O_NOCTTY | O_NONBLOCK);
    if (fd < 0) {
        log_warning("cannot open the link serial:%s@%ld: cannot open serial port %s: %s", a->path,
                    a->baud, a->path, strerror(errno));
        return -1;
    }
    struct termios tio;
    if (tcgetattr(fd, &tio) == 0) {
        /* raw 8N1, no flow control, reads that never wait (pyserial's settings) */
        tio.c_iflag &= ~(tcflag_t)(IGNBRK | BRKINT | PARMRK | ISTRIP | INLCR | IGNCR | ICRNL |
                                   IXON | IXOFF | IXANY | INPCK);
        tio.c_oflag &= ~(tcflag_t)OPOST;
        tio.c_lflag &= ~(tcflag_t)(ECHO | ECHONL | ICANON | ISIG | IEXTEN | ECHOE | ECHOK);
        tio.c_cflag &= ~(tcflag_t)(CSIZE | PARENB | CSTOPB);
        tio.c_cflag |= CS8 | CLOCAL | CREAD;
        tio.c_cc[VMIN] = 0;
        tio.c_cc[VTIME] = 0;
        speed_t speed = speed_of(a->baud);
        if (speed != B0) {
            cfsetispeed(&tio, speed);
            cfsetospeed(&tio, speed);
        } else {
            log_warning("serial:%s: baud %ld is not a standard rate; the line keeps its own",
                        a->path, a->baud);
        }
        tcsetattr(fd, TCSANOW, &tio);
    }
    t->fd = fd;
    t->udp = 0;
    t->baud = (double)a->baud;
    t->free_at = 0.0;
    double slice = t->baud / 10 * SLICE_SECONDS + 0.5;
    t->slice = slice < 1.0 ? 1 : (size_t)slice;
    return 0;
}

static int serial_flush(Transport *t, double now);

static void transport_send(Transport *t, const uint8_t *frame, size_t size, double now) {
    if (t->udp) {
        if (send(t->fd, frame, size, 0) < 0) t->send_failures++;
        else t->sent++;
        return;
    }
    static uint8_t encoded[LINK_MAX_ENCODED_BYTES + 16];
    long n = serial_encode(frame, size, encoded, sizeof encoded);
    if (n < 0 || t->pending_used + (size_t)n > MAX_PENDING_BYTES ||
        t->queued >= (int)(sizeof t->done / sizeof t->done[0])) {
        t->send_failures++; /* the line is that far behind: the frame is lost */
        return;
    }
    /* PacedLine: its bytes arrive one after another from when the line is free, 8N1 */
    double start = now > t->free_at ? now : t->free_at;
    t->free_at = start + (double)n * 10 / t->baud;
    memcpy(t->pending + t->pending_used, encoded, (size_t)n);
    t->pending_used += (size_t)n;
    t->start[t->queued] = start;
    t->done[t->queued] = t->free_at;
    t->size[t->queued] = (size_t)n;
    t->queued++;
    serial_flush(t, now);
}

/* -1: the line is gone */
static int serial_flush(Transport *t, double now) {
    if (t->udp) return 0;
    int taken = 0;
    /* the bytes the line has carried by now join what is due, frame after frame */
    while (taken < t->queued) {
        size_t size = t->size[taken], upto = size;
        if (now < t->done[taken]) {
            double carried = (now - t->start[taken]) * t->baud / 10 + 1e-6;
            upto = carried <= 0.0 ? 0 : carried >= (double)size ? size : (size_t)carried;
        }
        if (upto > t->handed) {
            t->unwritten += upto - t->handed;
            t->handed = upto;
        }
        if (t->handed < size) break;
        t->handed = 0;
        taken++;
    }
    if (taken) {
        size_t rest = sizeof(double) * (size_t)(t->queued - taken);
        memmove(t->start, t->start + taken, rest);
        memmove(t->done, t->done + taken, rest);
        memmove(t->size, t->size + taken, sizeof(size_t) * (size_t)(t->queued - taken));
        t->queued -= taken;
        t->sent += taken;
    }
    size_t written = 0;
    while (written < t->unwritten) {
        ssize_t n = write(t->fd, t->pending + written, t->unwritten - written);
        if (n < 0) {
            if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) break;
            return -1;
        }
        if (n == 0) break;
        written += (size_t)n;
    }
    if (written) {
        memmove(t->pending, t->pending + written, t->pending_used - written);
        t->pending_used -= written;
        t->unwritten -= written;
    }
    return 0;
}

/* when the next slice of bytes is due */
static double transport_deadline(const Transport *t) {
    if (t->udp || t->queued == 0) return INFINITY;
    size_t upto = t->handed + t->slice;
    if (upto >= t->size[0]) return t->done[0];
    return t->start[0] + (double)upto * 10 / t->baud;
}

typedef struct {
    LinkRobot *program;
    double now;
} FeedContext;

static void on_frame(void *ctx, uint8_t *frame, size_t size, int refusal) {
    FeedContext *fc = ctx;
    if (frame == NULL) {
        transport.refused[refusal]++;
        return;
    }
    link_robot_receive(fc->program, frame, size, fc->now);
}

/* -1: the transport is gone */
static int transport_receive(Transport *t, LinkRobot *program, double now) {
    static uint8_t data[LINK_MAX_FRAME_BYTES + 1];
    if (t->udp) {
        for (int i = 0; i < MAX_DATAGRAMS_PER_RECEIVE; i++) {
            ssize_t n = recv(t->fd, data, sizeof data, 0);
            if (n < 0) {
                if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) break;
                if (errno == ECONNREFUSED) continue; /* an earlier datagram found no bridge */
                return -1;
            }
            if ((size_t)n > LINK_MAX_FRAME_BYTES) {
                t->refused[R_OVERSIZE]++;
                continue;
            }
            link_robot_receive(program, data, (size_t)n, now);
        }
        return 0;
    }
    static uint8_t chunk[READ_BYTES];
    ssize_t n = read(t->fd, chunk, sizeof chunk);
    if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) return 0;
        return -1;
    }
    if (n == 0) return -1; /* readable, and no data: the device is gone */
    FeedContext fc = {program, now};
    deframer_feed(&t->deframer, chunk, (size_t)n, on_frame, &fc);
    return 0;
}

/* --- the loop (program.py serve, _exchange, _drain) ---------------------------------- */

static volatile sig_atomic_t stop_requested;
static void on_signal(int signum) {
    (void)signum;
    stop_requested = 1;
}

static void send_outgoing(LinkRobot *program, Transport *t, double now) {
    size_t size;
    const uint8_t *frame;
    for (int i = 0; (frame = client_frame(&program->client, i, &size)) != NULL; i++)
        transport_send(t, frame, size, now);
    client_clear(&program->client);
}

static int serve(LinkRobot *program, const Address *address, double give_up) {
    int open_ = 0;
    double reopen_at = 0.0;
    double alone_since = now_monotonic();
    while (!program->ended && !stop_requested) {
        double now = now_monotonic();
        if (!open_ && now >= reopen_at) {
            if (open_transport(address, &transport) == 0) open_ = 1;
            else reopen_at = now + REOPEN_EVERY;
        }
        if (program->client.open) {
            alone_since = now;
        } else if (give_up > 0 && now - alone_since > give_up) {
            if (address->udp)
                log_error("no bridge answered on udp://%s:%s for %g s: giving up", address->host,
                          address->port, give_up);
            else
                log_error("no bridge answered on serial:%s@%ld for %g s: giving up", address->path,
                          address->baud, give_up);
            if (open_) close(transport.fd);
            return 1;
        }
        link_robot_wake(program, now);
        if (!open_) {
            client_clear(&program->client); /* no link to carry them */
            double wait = reopen_at - now_monotonic();
            wait = wait < MAX_WAIT ? wait : MAX_WAIT;
            if (wait > 0) {
                struct timespec ts = {(time_t)wait, (long)((wait - floor(wait)) * 1e9)};
                nanosleep(&ts, NULL);
            }
            continue;
        }
        int gone = 0;
        send_outgoing(program, &transport, now);
        if (serial_flush(&transport, now) < 0) gone = 1;
        double deadline = link_robot_deadline(program);
        double td = transport_deadline(&transport);
        if (td < deadline) deadline = td;
        double wait = deadline - now_monotonic();
        wait = wait > 0.0 ? wait : 0.0;
        wait = wait < MAX_WAIT ? wait : MAX_WAIT;
        fd_set readable;
        FD_ZERO(&readable);
        FD_SET(transport.fd, &readable);
        struct timeval tv = {(time_t)wait, (suseconds_t)((wait - floor(wait)) * 1e6)};
        int ready = gone ? 0 : select(transport.fd + 1, &readable, NULL, NULL, &tv);
        if (ready > 0) {
            now = now_monotonic();
            if (transport_receive(&transport, program, now) < 0) gone = 1;
            else if (!transport.udp && deframer_receiving(&transport.deframer))
                link_robot_hearing(program, now); /* a long frame under way is not silence */
            send_outgoing(program, &transport, now); /* answer at once */
            if (serial_flush(&transport, now) < 0) gone = 1;
        }
        if (gone) {
            log_warning("the link closed; reopening it");
            close(transport.fd);
            open_ = 0;
            reopen_at = now + REOPEN_EVERY;
        }
    }
    if (open_) {
        link_robot_stop(program);
        double now = now_monotonic();
        send_outgoing(program, &transport, now);
        double deadline = now + DRAIN_WAIT;
        while (!transport.udp && (transport.queued || transport.unwritten) &&
               now_monotonic() < deadline) {
            struct timespec ts = {0, 20 * 1000 * 1000};
            nanosleep(&ts, NULL);
            if (serial_flush(&transport, now_monotonic()) < 0) break;
        }
        serial_flush(&transport, now_monotonic());
        close(transport.fd);
    }
    return 0;
}

/* --- the command line (program.py build_parser) -------------------------------------- */

static const char *const OPTIONS[] = {"--link", "--id", "--key-file", "--give-up", "--log-level",
                                      "--help", NULL};

static const char *resolve(const char *given) {
    size_t n = strlen(given);
    const char *match = NULL;
    int matches = 0;
    for (int i = 0; OPTIONS[i]; i++) {
        if (!strcmp(OPTIONS[i], given)) return OPTIONS[i];
        if (!strncmp(OPTIONS[i], given, n)) {
            match = OPTIONS[i];
            matches++;
        }
    }
    if (matches == 1 && n > 2) return match;
    if (matches > 1 && n > 2) usage_error("ambiguous option: %s%s", given, "");
    return NULL;
}

int main(int argc, char **argv) {
    const char *link_text = NULL, *id_text = NULL, *key_file = NULL, *give_up_text = NULL;
    const char *level_text = "info";
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i];
        if (!strcmp(arg, "-h")) arg = "--help";
        if (strncmp(arg, "--", 2) != 0 || !strcmp(arg, "--"))
            usage_error("unrecognized arguments: %s%s", arg, "");
        char name[64];
        const char *value = NULL;
        const char *eq = strchr(arg, '=');
        size_t nn = eq ? (size_t)(eq - arg) : strlen(arg);
        if (nn >= sizeof name) usage_error("unrecognized arguments: %s%s", arg, "");
        memcpy(name, arg, nn);
        name[nn] = 0;
        const char *option = resolve(name);
        if (option == NULL) usage_error("unrecognized arguments: %s%s", arg, "");
        if (!strcmp(option, "--help")) {
            fputs(USAGE, stdout);
            puts("\nOne robot of a run, outside the emulator: its controller over a link (UDP "
                 "or serial) to the run's bridge\n(swarm run --external ... --link ...), in C.\n\n"
                 "options:\n"
                 "  -h, --help            show this help message and exit\n"
                 "  --link ADDRESS        the bridge: udp://HOST:PORT, or serial:PATH[@BAUD] "
                 "(default baud 115200)\n"
                 "  --id ID               the robot's id\n"
                 "  --key-file FILE       the robot's run key (swarm run writes robot-ID.key; "
                 "never on a command line)\n"
                 "  --give-up SECONDS     exit with code 1 when no bridge has answered for this "
                 "long (default: keep trying)\n"
                 "  --log-level {debug,info,warning,error}\n"
                 "                        default: info");
            return 0;
        }
        if (eq) {
            value = eq + 1;
        } else {
            if (i + 1 >= argc || (argv[i + 1][0] == '-' && argv[i + 1][1] == '-'))
                usage_error("argument %s: expected one argument%s", option, "");
            value = argv[++i];
        }
        if (!strcmp(option, "--link")) link_text = value;
        else if (!strcmp(option, "--id")) id_text = value;
        else if (!strcmp(option, "--key-file")) key_file = value;
        else if (!strcmp(option, "--give-up")) give_up_text = value;
        else level_text = value;
    }
    if (!link_text || !id_text || !key_file) {
        char missing[64] = "";
        if (!link_text) strcat(missing, "--link");
        if (!id_text) strcat(missing, missing[0] ? ", --id" : "--id");
        if (!key_file) strcat(missing, missing[0] ? ", --key-file" : "--key-file");
        usage_error("the following arguments are required: %s%s", missing, "");
    }
    Address address;
    if (parse_address(link_text, &address) != 0) {
        const char *what = !strncmp(link_text, "udp://", 6) ? "a UDP link is udp://HOST:PORT"
                           : !strncmp(link_text, "serial:", 7) ? "a serial link is serial:PATH[@BAUD]"
                           : "a link is udp://HOST:PORT or serial:PATH[@BAUD]";
        usage_error("argument --link: '%s': %s", link_text, what);
    }
    size_t idn = strlen(id_text);
    if (!all_digits(id_text) || idn > 6 || (id_text[0] == '0' && idn > 1) || atol(id_text) >= MAX_ROBOTS)
        usage_error("argument --id: '%s' is not a robot id (0 to 99999)%s", id_text, "");
    int robot = (int)atol(id_text);
    double give_up = 0.0;
    if (give_up_text) {
        char *end;
        give_up = strtod(give_up_text, &end);
        if (*end || end == give_up_text)
            usage_error("argument --give-up: '%s' is not a number%s", give_up_text, "");
        if (!isfinite(give_up) || give_up <= 0)
            usage_error("argument --give-up: '%s' is not a positive number of seconds%s", give_up_text, "");
    }
    if (!strcmp(level_text, "debug")) log_level = LOG_DEBUG;
    else if (!strcmp(level_text, "info")) log_level = LOG_INFO;
    else if (!strcmp(level_text, "warning")) log_level = LOG_WARNING;
    else if (!strcmp(level_text, "error")) log_level = LOG_ERROR;
    else usage_error("argument --log-level: invalid choice: '%s' (choose from debug, info, warning, error)%s", level_text, "");
    log_robot = robot;

    static char run[MAX_NAME + 1];
    uint8_t key[32];
    read_key_file(key_file, robot, run, key);

    struct sigaction action;
    memset(&action, 0, sizeof action);
    action.sa_handler = on_signal;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, NULL);
    sigaction(SIGTERM, &action, NULL);
    signal(SIGPIPE, SIG_IGN);

    static LinkRobot program;
    if (link_robot_init(&program, robot, run, key) != 0) {
        log_error("robot %d: no source of random bytes for the link's nonces: cannot run",
                  robot);
        return 1;
    }
    log_info("robot %d of run %s: saying hello on %s", robot, run, link_text);
    int code = serve(&program, &address, give_up);
    static char summary[4096];
    link_robot_summary(&program, summary, sizeof summary);
    printf("%s\n", summary);
    fflush(stdout);
    if (program.fatal && code == 0) code = 1;
    return code;
}
