/*
 * srv_signal.h - the daemon's signal handlers and the flags they set
 * (srv_signal.c).  Main thread only.
 */
#ifndef SRV_SIGNAL_H
#define SRV_SIGNAL_H

/* Installs the handlers of SIGINT, SIGTERM and SIGHUP and ignores
 * SIGPIPE and SIGXFSZ. */
void srv_signal_install(void);
/* The stop signal received (SIGINT or SIGTERM), or 0. */
int srv_signal_stop(void);
/* 1 once after a SIGHUP (the flag is cleared), else 0. */
int srv_signal_hup(void);

#endif
