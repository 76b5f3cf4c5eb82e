/*
 * srv_config.h - the daemon's settings: defaults, then a config file, then
 * the environment, then the command line, each overriding the one before.
 * Every value is range-checked and an error names the source (flag, file
 * and line, or variable) and the limit.
 */
#ifndef SRV_CONFIG_H
#define SRV_CONFIG_H

#include <stddef.h>

#include "mpp.h"
#include "mpp_endpoint.h"

typedef struct {
    char endpoint[256];             /* control socket (ROUTER) */
    char stream_endpoint[256];      /* job streams (XPUB); "" = derived */
    char endpoint_from[160];        /* where each was set (a flag, a variable, FILE:LINE), */
    char stream_endpoint_from[160]; /* for the messages of the bind rule */
    char db[1024];                  /* SQLite file */
    int workers;                    /* jobs run at once */
    int solver_threads;             /* threads per job (a case may ask for fewer) */
    int queue_max;                  /* queued jobs beyond the running ones */
    long long max_particles;        /* per job */
    long long max_steps;            /* per job */
    double max_wall_s;              /* per job, 0 = none */
    double checkpoint_every_s;      /* checkpoint interval of a case without one, 0 = none */
    double checkpoint_share;        /* share of a job's wall time its checkpoints may take */
    int disk_reserve_mb;            /* the store's disk reserve (0: none) */
    long long max_request_bytes;    /* largest request accepted */
    int stream_buffer_mb;           /* MB queued for one watcher, all its jobs (0: no bound) */
    int stream_total_mb;            /* MB of snapshots queued for all watchers (0: no bound) */
    int stream_max_subscriptions;   /* subscriptions held for all watchers */
    int stream_subscribe_ahead;     /* job ids past the newest a watcher may subscribe to */
    int connection_reply_buffer_mb; /* MiB of unread replies per connection */
    int reply_buffer_mb;            /* MiB of unread replies, all connections */
    long long page_max_bytes;       /* largest energy page or runs listing */
    int page_max_ms;                /* longest a runs listing is made for */
    int max_connections;            /* request connections at once, 0 = no cap */
    int handshake_timeout_s;        /* a connection's handshake, seconds */
    int allow_remote;               /* deprecated: non-loopback binds need CURVE now */
    int insecure_remote;            /* --insecure-allow-remote-without-auth */
    char curve_secret[1024];        /* server secret key file ("": no CURVE) */
    char authorized_keys[1024];     /* client public keys: file or directory */
    char admin_keys[1024];          /* admin public keys: file or directory */
    int client_max_jobs;            /* live (queued + running) jobs per client, 0 = no limit */
    long long client_max_particles; /* particles per job of one client, 0 = no limit */
    long long client_max_disk_mb;   /* MiB of stored records per client, 0 = no limit */
    long long job_max_disk_mb;      /* MiB of stored records per job, 0 = no limit */
    long long max_disk_mb;          /* MiB of stored records in the database, 0 = no limit */
    int private_runs;               /* a client reads only its own runs (admins: all) */
    int portable_kernels;           /* every job on MPM_KERNELS_PORTABLE */
    int verbose;
} srv_config;

/* Fills c from defaults, --config FILE, MPMD_* variables and argv.
 * Returns 0 to run, 1 when --help or --version was printed (exit 0), or -1
 * with a message in err (exit 2). */
int srv_config_load(srv_config *c, int argc, char **argv, char *err, size_t errlen);

#endif
