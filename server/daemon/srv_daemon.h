/*
 * srv_daemon.h - the mpmd daemon: binds the sockets, opens the store,
 * starts the workers and serves requests until SIGINT or SIGTERM.
 */
#ifndef SRV_DAEMON_H
#define SRV_DAEMON_H

#include "srv_config.h"

/* Runs the daemon; returns the process exit status (0 after a clean
 * shutdown, 1 if it could not start). */
int srv_daemon_run(const srv_config *cfg);

#endif
