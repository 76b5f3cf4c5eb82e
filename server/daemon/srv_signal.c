/*
 * srv_signal.c - the daemon's signals: SIGINT and SIGTERM ask it to stop,
 * SIGHUP to re-read the key lists; SIGPIPE and SIGXFSZ are ignored (over
 * a file-size limit a write fails with EFBIG, as on a full disk, instead
 * of killing the daemon).  The handlers only set flags, which the main
 * thread reads (srv_daemon.c's loop, and a Submit that arrives in the
 * same turn as the signal: srv_submit.c).
 */
#include "srv_signal.h"

#include <signal.h>
#include <string.h>

static volatile sig_atomic_t stop_signal, hup_signal;

static void on_signal(int sig)
{
    stop_signal = sig;
}

static void on_hup(int sig)
{
    (void)sig;
    hup_signal = 1;
}

void srv_signal_install(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sa.sa_handler = on_hup;
    sigaction(SIGHUP, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
    signal(SIGXFSZ, SIG_IGN);
}

int srv_signal_stop(void)
{
    return stop_signal;
}

int srv_signal_hup(void)
{
    if (!hup_signal) return 0;
    hup_signal = 0;
    return 1;
}
