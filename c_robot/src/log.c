#include "log.h"

#include <stdarg.h>
#include <stdio.h>

int log_level = LOG_INFO;
int log_robot = -1;

static void to_stderr(const char *line, size_t size) { fwrite(line, 1, size, stderr); }

void (*log_sink)(const char *line, size_t size) = to_stderr;

void log_at(int level, const char *format, ...) {
    if (level < log_level) return;
    const char *name = level >= LOG_ERROR ? "ERROR" : level >= LOG_WARNING ? "WARNING"
                       : level >= LOG_INFO ? "INFO" : "DEBUG";
    char line[LOG_LINE_BYTES];
    int n = snprintf(line, sizeof line, "c-robot[link %d] %s ", log_robot, name);
    va_list args;
    va_start(args, format);
    n += vsnprintf(line + n, sizeof line - (size_t)n, format, args);
    va_end(args);
    if (n > (int)sizeof line - 2) n = (int)sizeof line - 2; /* a longer line is cut */
    line[n++] = '\n';
    log_sink(line, (size_t)n);
}
