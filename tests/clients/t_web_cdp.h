/*
 * t_web_cdp.h - headless Chromium driven over the DevTools protocol on a
 * pipe (--remote-debugging-pipe: JSON messages ending in a NUL byte, the
 * browser reading fd 3 and writing fd 4), for the web monitor's test: open
 * a page, evaluate expressions in it while it updates live, take
 * screenshots.  No WebSocket, no virtual time: the page runs in real time,
 * its event stream open, and the test reads what it drew whenever it asks.
 */
#ifndef T_WEB_CDP_H
#define T_WEB_CDP_H

#include <stddef.h>
#include <sys/types.h>

#include <jansson.h>

typedef struct {
    pid_t pid;
    int wfd, rfd; /* to the browser (its fd 3), from it (its fd 4) */
    char *buf;    /* bytes read, not yet a whole message */
    size_t n, cap;
    int next_id;
    char session[128]; /* the page's session (flat mode) */
} cdp_t;

/* Starts `browser` (e.g. /usr/bin/chromium) headless with its profile in
 * profile_dir and its stderr appended to errlog.  0 or -1. */
int cdp_open(cdp_t *c, const char *browser, const char *profile_dir, const char *errlog);
/* Opens url in a new page of w x h CSS pixels and attaches to it. */
int cdp_page(cdp_t *c, const char *url, int w, int h);
/* One command (params consumed, may be NULL) on the page's session
 * (page != 0) or the browser; its result object (new reference), or NULL
 * on an error or after timeout s. */
json_t *cdp_call(cdp_t *c, int page, const char *method, json_t *params, double timeout);
/* Evaluates a JavaScript expression in the page; its value as a string
 * into out (JSON text for non-strings).  0 or -1. */
int cdp_eval(cdp_t *c, const char *expr, char *out, size_t n);
/* A PNG of the page's viewport into path.  0 or -1. */
int cdp_screenshot(cdp_t *c, const char *path);
/* Closes the browser (Browser.close, then SIGKILL if it lingers). */
void cdp_close(cdp_t *c);

#endif
