/* The limits of a robot on a microcontroller (src/limits.h): runs of up to 10 sites and 16
   robots, and the world's camera frames, 64 x 48 RGB PNGs (noise makes them larger: at
   most about 9.3 KB, their 9,264 bytes of rows stored uncompressed). Given to every compile
   of the firmware with -include. The RAM it takes is measured by the build (make -C c_robot
   firmware prints it; docs/porting.md, "On a microcontroller"). A map, a message or a
   frame past these is refused and counted, never overrun. */
#ifndef CR_PROFILE_MCU_H
#define CR_PROFILE_MCU_H

#define MAX_OPTIONS 10
#define MAX_HEARD 16
#define HEARD_DOUBLES (MAX_HEARD * MAX_OPTIONS)

/* a tick's inputs: a camera frame and the radio of the robots in range */
#define PENDING_BYTES (12 * 1024)
#define PENDING_MESSAGES 32

#define MAX_FRAME_PIXELS (64 * 48)
#define MAX_FRAME_BYTES (10 * 1024)
#define PNG_RAW_BYTES (MAX_FRAME_PIXELS * 4 + 64)

/* a camera frame on the link: its PNG, CameraMeta, tags and headers */
#define LINK_FRAME_CAP (MAX_FRAME_BYTES + 512)

#define OUT_QUEUE_BYTES 4096
#define OUT_QUEUE_FRAMES 16
#define STATUS_BYTES 1024
#define RADIO_TX_BYTES 1024
#define WELCOME_CONTROLLER_BYTES 1536

#define NAV_MAX_TRAIL 64
#define MAX_RINGS 8
#define MAX_RING_SLOTS 128

#define LOGGED_SOURCES 8
#define KEY_FILE_BYTES 2048
#define KEY_FILE_VALUE_BYTES 512

#endif
