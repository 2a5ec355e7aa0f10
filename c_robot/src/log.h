#ifndef CR_LOG_H
#define CR_LOG_H
#include <stddef.h>

enum { LOG_DEBUG = 10, LOG_INFO = 20, LOG_WARNING = 30, LOG_ERROR = 40 };
#define LOG_LINE_BYTES 512

extern int log_level;
extern int log_robot;
/* Where each line goes, with its newline: standard error unless the platform says (a
   firmware's log UART). */
extern void (*log_sink)(const char *line, size_t size);
void log_at(int level, const char *format, ...) __attribute__((format(printf, 2, 3)));
#define log_debug(...) log_at(LOG_DEBUG, __VA_ARGS__)
#define log_info(...) log_at(LOG_INFO, __VA_ARGS__)
#define log_warning(...) log_at(LOG_WARNING, __VA_ARGS__)
#define log_error(...) log_at(LOG_ERROR, __VA_ARGS__)
#endif
