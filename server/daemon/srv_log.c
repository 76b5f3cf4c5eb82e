/*
 * srv_log.c - timestamped log lines on stderr (see srv_log.h).  Each line is
 * formatted into a buffer first and written with one write(2), so lines
 * from worker threads never interleave.
 */
#include "srv_log.h"

#include "mpp_text.h"

#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static atomic_int verbose;

void srv_log_set_verbose(int v)
{
    atomic_store(&verbose, v);
}

static void emit(const char *level, uint64_t job, const char *fmt, va_list ap)
{
    char line[2048], msg[2048];
    struct timespec ts;
    struct tm tm;
    clock_gettime(CLOCK_REALTIME, &ts);
    gmtime_r(&ts.tv_sec, &tm);
    int n = snprintf(line, sizeof line, "%04d-%02d-%02dT%02d:%02d:%02d.%03ldZ mpmd %s ",
                     tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                     ts.tv_nsec / 1000000, level);
    if (job && n < (int)sizeof line)
        n += snprintf(line + n, sizeof line - (size_t)n, "job %llu: ", (unsigned long long)job);
    vsnprintf(msg, sizeof msg, fmt, ap);
    if (n < (int)sizeof line) n += (int)mpp_text_escape(msg, line + n, sizeof line - (size_t)n);
    if (n >= (int)sizeof line - 1) n = (int)sizeof line - 2;
    line[n++] = '\n';
    ssize_t w = write(STDERR_FILENO, line, (size_t)n);
    (void)w; /* nowhere to report a failed log write */
}

void srv_log(uint64_t job, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    emit("info", job, fmt, ap);
    va_end(ap);
}

void srv_warn(uint64_t job, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    emit("WARN", job, fmt, ap);
    va_end(ap);
}

void srv_error(uint64_t job, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    emit("ERROR", job, fmt, ap);
    va_end(ap);
}

void srv_debug(uint64_t job, const char *fmt, ...)
{
    if (!atomic_load(&verbose)) return;
    va_list ap;
    va_start(ap, fmt);
    emit("debug", job, fmt, ap);
    va_end(ap);
}

void srv_log_store(void *ud, const char *msg)
{
    (void)ud;
    /* a lost write is a warning (the store's other lines are information) */
    if (!strncmp(msg, "write failed", 12) || !strncmp(msg, "ROLLBACK", 8))
        srv_warn(0, "store: %s", msg);
    else
        srv_log(0, "store: %s", msg);
}

double srv_wall_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}
