/* Every compile-time limit of the robot, with its default: the host build's, for any map
   the protocol allows. A build for a microcontroller sets them all at once
   (platform/profile_mcu.h, given with -include), or one at a time with -DNAME=VALUE. A
   limit bounds what the robot holds, never what it accepts as valid: an input past one is
   refused and counted as one it cannot use (c_robot/README.md, "Limits"). */
#ifndef CR_LIMITS_H
#define CR_LIMITS_H

/* Sites in a map, and so options in an opinion. The protocol allows 1000
   (PROTOCOL_MAX_OPTIONS, messages.h); a map with more sites than this is refused at
   start, and a radio opinion longer than this is refused as one the robot cannot hold. */
#ifndef MAX_OPTIONS
#define MAX_OPTIONS 1000
#endif

/* Robots whose opinions are kept between two poolings (and, with the trimmed defence, the
   peers' latest), and their room in doubles: 6553 robots at 10 sites, 65 at 1000. When
   full, an entry no pooling can take any more is freed, else the new one is dropped. */
#ifndef MAX_HEARD
#define MAX_HEARD 4096
#endif
#ifndef HEARD_DOUBLES
#define HEARD_DOUBLES (1 << 16)
#endif
#define MAX_POOL (MAX_HEARD + 1) /* the robot and the neighbours heard at one visit */

/* Inputs held for ticks not reached (Python holds 4 MiB and 4000 messages). */
#ifndef PENDING_BYTES
#define PENDING_BYTES (1024 * 1024)
#endif
#ifndef PENDING_MESSAGES
#define PENDING_MESSAGES 4000
#endif

/* Camera frames: pixels (Python takes up to 10^6) and PNG bytes. A larger frame is refused
   and counted, as a frame that is no image. PNG_RAW_BYTES holds a frame inflated, one
   filter byte a row, 4 channels at most. */
#ifndef MAX_FRAME_PIXELS
#define MAX_FRAME_PIXELS (320 * 240)
#endif
#ifndef MAX_FRAME_BYTES
#define MAX_FRAME_BYTES (1024 * 1024)
#endif
#ifndef PNG_RAW_BYTES
#define PNG_RAW_BYTES (MAX_FRAME_PIXELS * 4 + 4096)
#endif

/* The largest link frame this build holds as it arrives (the protocol's largest is 65507
   bytes, a UDP datagram): a longer serial chunk is refused as `oversize`. */
#ifndef LINK_FRAME_CAP
#define LINK_FRAME_CAP 65507
#endif

/* What the robot sends: the frames of one turn of its loop, a status and a radio opinion
   (JSON), and the welcome's controller settings it keeps (the run's are about 700 bytes;
   a larger welcome is refused as `malformed`). */
#ifndef OUT_QUEUE_BYTES
#define OUT_QUEUE_BYTES (512 * 1024)
#endif
#ifndef OUT_QUEUE_FRAMES
#define OUT_QUEUE_FRAMES 256
#endif
#ifndef STATUS_BYTES
#define STATUS_BYTES (32 * 1024)
#endif
#ifndef RADIO_TX_BYTES
#define RADIO_TX_BYTES (32 * 1024)
#endif
#ifndef WELCOME_CONTROLLER_BYTES
#define WELCOME_CONTROLLER_BYTES 8192
#endif

/* The navigator's trail of positions (its stuck window plus one: 31 at the default control
   period), and the parking rings (rings from the wall in, and slots on one ring). */
#ifndef NAV_MAX_TRAIL
#define NAV_MAX_TRAIL 8192
#endif
#ifndef MAX_RINGS
#define MAX_RINGS 4096
#endif
#ifndef MAX_RING_SLOTS
#define MAX_RING_SLOTS 16384
#endif

/* math.fsum keeps at most one partial per value summed, and the robot sums at most an
   opinion's MAX_OPTIONS values. */
#ifndef FSUM_PARTIALS
#define FSUM_PARTIALS MAX_OPTIONS
#endif

/* Sources of invalid messages logged once each; past these, each is logged every time. */
#ifndef LOGGED_SOURCES
#define LOGGED_SOURCES 32
#endif

/* A key file: its bytes, and one string value in it. */
#ifndef KEY_FILE_BYTES
#define KEY_FILE_BYTES 65536
#endif
#ifndef KEY_FILE_VALUE_BYTES
#define KEY_FILE_VALUE_BYTES 8192
#endif

#endif
