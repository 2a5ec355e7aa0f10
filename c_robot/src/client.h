/* The robot's end of a link session (bestofn_swarm/link/core/session.py) and the program around
   the endpoint (robot_agent/core/link_robot.py), without I/O. */
#ifndef CR_CLIENT_H
#define CR_CLIENT_H
#include <stddef.h>
#include <stdint.h>

#include "endpoint.h"
#include "link.h"

#define HELLO_EVERY 0.5
#define SILENCE_BEFORE_WELCOME 3.0
#define ASK_EVERY 1.0
#define STATUS_EVERY 2.0
/* A world token the bridge reports is followed once that world answers world/info asked
   with the token's instance: asked up to PROVE_TRIES times, PROVE_EVERY seconds apart; a
   token no world answers for is counted as a rejection (robot_agent/core/link_robot.py). */
#define PROVE_TRIES 5
#define PROVE_EVERY 2.0
/* A question asked again does not void the ones before it: an answer to any of the last
   RECENT_QUESTIONS counts, so a relay slower than ASK_EVERY or PROVE_EVERY still brings
   the map and the proofs. */
#define RECENT_QUESTIONS 8

/* the nonces of a question's last askings, oldest first */
typedef struct {
    uint8_t nonces[RECENT_QUESTIONS][16];
    int count;
} Questions;

/* the nonce of the latest asking */
const uint8_t *questions_latest(const Questions *q);

typedef struct {
    uint32_t robot;
    uint8_t key[32]; /* the link key */
    long refused[R_COUNT];
    long sessions;
    int has_welcome;
    char run[MAX_NAME + 1], root[MAX_NAME + 1];
    int encrypted;
    double ping_every;
    uint8_t controller[WELCOME_CONTROLLER_BYTES];
    size_t controller_size;
    uint8_t robot_nonce[8], bridge_nonce[8];
    int open;
    int has_cipher;
    uint8_t cipher_key[32];
    uint64_t sent_seq;
    ReplayWindow window;
    double next_hello, last_heard, silence;
    /* frames to send, in order */
    uint8_t queue[OUT_QUEUE_BYTES];
    size_t queue_used;
    size_t frame_size[OUT_QUEUE_FRAMES];
    int frame_count;
    long queue_dropped;
} LinkClient;

typedef struct {
    int robot;
    char run[MAX_NAME + 1];
    uint8_t robot_key[32];
    char identity[32];
    LinkClient client;
    int has_endpoint;
    Endpoint *endpoint;
    char worlds[MAX_WORLDS][MAX_NAME + 1];
    int world_count;
    int asking;
    Questions asked; /* the question for the map */
    double ask_again_at;
    /* world tokens being proved, in the order their questions were asked */
    struct {
        char instance[MAX_NAME + 1];
        Questions asked;
        double again_at;
        int tries;
    } proving[MAX_WORLDS];
    int proving_count;
    int ended;
    int has_last_status;
    uint8_t last_status[STATUS_BYTES];
    size_t last_status_size;
    uint8_t last_status_attachment[32];
    double status_again_at;
    long dropped[3]; /* sense, camera, radio_rx inputs before the map */
    int fatal; /* the map or the settings could not be used: exit 1 */
} LinkRobot;

/* 0, or -1: the platform gives no random bytes for the first nonce (the robot cannot run) */
int link_robot_init(LinkRobot *p, int robot, const char *run, const uint8_t robot_key[32]);
double link_robot_deadline(const LinkRobot *p);
void link_robot_wake(LinkRobot *p, double now);
/* one frame from the link (decrypted in place: data is the caller's, changed) */
void link_robot_receive(LinkRobot *p, uint8_t *data, size_t size, double now);
/* Bytes of a frame are arriving on a serial line (its zero not yet): the bridge is there,
   so an open session's silence counts from now, and no question is asked again while the
   frame comes (it may be the answer: a map of 1000 sites takes 5 s at 115200 baud). */
void link_robot_hearing(LinkRobot *p, double now);
void link_robot_stop(LinkRobot *p);
/* the frames to send: call with index 0.. until it returns NULL, then clear */
const uint8_t *client_frame(LinkClient *c, int index, size_t *size);
void client_clear(LinkClient *c);
/* the program's last line (program.py summary) */
void link_robot_summary(const LinkRobot *p, char *out, size_t cap);
#endif
