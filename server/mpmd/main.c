/*
 * main.c - mpmd's entry point: reads the settings and runs the daemon.
 */
#include "srv_config.h"
#include "srv_daemon.h"

#include <stdio.h>

int main(int argc, char **argv)
{
    srv_config cfg;
    char err[1024];
    int rc = srv_config_load(&cfg, argc, argv, err, sizeof err);
    if (rc > 0) return 0;
    if (rc < 0) {
        fprintf(stderr, "mpmd: %s\n", err);
        return 2;
    }
    return srv_daemon_run(&cfg);
}
