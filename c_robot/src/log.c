#include "log.h"

#include <stdarg.h>
#include <stdio.h>

int log_level = LOG_INFO;
int log_robot = -1;

void log_at(int level, const char *format, ...) {
    if (level < log_level) return;
    const char *name = level >= LOG_ERROR ? "ERROR" : level >= LOG_WARNING ? "WARNING"
                       : level >= LOG_INFO ? "INFO" : "DEBUG";
    fprintf(stderr, "c-robot[link %d] %s ", log_robot, name);
    va_list args;
    va_start(args, format);
    vfprintf(stderr, format, args);
    va_end(args);
    fputc('\n', stderr);
}
