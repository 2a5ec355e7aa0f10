/* Generated from the table of message kinds (bestofn_swarm/wire/keyspace.py) by
   `python -m bestofn_swarm.wire.keyspace --c-header`: do not edit.
   tests/test_keyspace.py fails when it is stale. */
#ifndef KINDS_H
#define KINDS_H

/* What a DATA frame of the link carries (docs/protocol.md): codes below
   K_FIRST_FROM_ROBOT go to the robot, the others come from it. */
enum data_kind {
    K_SENSE = 1, /* sense: message */
    K_CAMERA = 2, /* camera: message */
    K_RADIO_RX = 3, /* radio_rx: message */
    K_INFO_REPLY = 4, /* info: reply */
    K_INFO_ERROR = 5, /* info: error */
    K_WORLD_UP = 6, /* alive_world: message */
    K_WORLD_DOWN = 7, /* alive_world: gone */
    K_ACT = 16, /* act: message */
    K_RADIO_TX = 17, /* radio_tx: message */
    K_STATUS = 18, /* status: message */
    K_INFO_QUERY = 19, /* info: message */
    K_FIRST_FROM_ROBOT = 16
};

/* Whether a DATA frame's kind is one of the link's. */
static inline int kind_known(int kind) {
    switch (kind) {
    case K_SENSE:
    case K_CAMERA:
    case K_RADIO_RX:
    case K_INFO_REPLY:
    case K_INFO_ERROR:
    case K_WORLD_UP:
    case K_WORLD_DOWN:
    case K_ACT:
    case K_RADIO_TX:
    case K_STATUS:
    case K_INFO_QUERY:
        return 1;
    default:
        return 0;
    }
}

#endif
