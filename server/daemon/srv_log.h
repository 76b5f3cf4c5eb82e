/*
 * srv_log.h - the daemon's log: one line per event on stderr, with a UTC
 * timestamp, the level and the job id when there is one.  Safe to call from
 * any thread (one write per line).
 */
#ifndef SRV_LOG_H
#define SRV_LOG_H

#include <stdint.h>

/* Logs a line; job 0 means "no job".  Debug lines show only when verbose.
 * srv_error is for what stops the daemon (a failed start).  The message
 * is written escaped by mpp_text_escape (a newline or an ESC in a case
 * name as \n, \x1b; a backslash as \\; U+202E as \u202e), so a line can
 * never be forged, split or reordered on screen. */
void srv_log(uint64_t job, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
void srv_warn(uint64_t job, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
void srv_error(uint64_t job, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
void srv_debug(uint64_t job, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
void srv_log_set_verbose(int verbose);

/* Unix time now, in seconds. */
double srv_wall_now(void);

/* A store_log_fn-compatible sink (user data unused). */
void srv_log_store(void *ud, const char *msg);

#endif
