/*
 * srv_auth.h - the daemon's authentication: CURVE on its sockets, the
 * allow-list of client public keys (and the admin keys) and the ZAP
 * handler thread that checks every CURVE handshake against them.
 *
 * With --curve-secret the request and stream sockets are CURVE servers in
 * the ZAP domain "mpmd"; libzmq asks the handler (a REP socket on
 * inproc://zeromq.zap.01, its own thread) about every client key, and the
 * handler accepts only the keys listed in --authorized-keys or
 * --admin-keys, with the key's Z85 text as the user id that every message
 * of the connection carries ("User-Id"): the run's owner.  The lists are
 * re-read by srv_auth_reload() (SIGHUP); a list that no longer reads keeps
 * the previous one and the error is logged.
 */
#ifndef SRV_AUTH_H
#define SRV_AUTH_H

#include <stddef.h>
#include <zmq.h>

#include "srv_config.h"

/* Z85 text of a 32-byte key, and its buffer size. */
#define SRV_KEY_Z85_LEN 40
#define SRV_KEY_Z85_SIZE 41

/* The owner of a request that came without CURVE (loopback, ipc://). */
#define SRV_OWNER_LOCAL "local"

typedef struct srv_auth srv_auth;

/* Reads a key file: the first line that is neither blank nor a '#'
 * comment holds the 40-character Z85 key (a comment may follow it).  With
 * secret != 0 the file must be mode 0600 or stricter (no group or other
 * bits).  Returns 0 with the key in z85 (SRV_KEY_Z85_SIZE bytes), or -1
 * with a message naming the file. */
int srv_key_file_read(const char *path, int secret, char *z85, char *err, size_t errlen);

/* Loads what cfg asks for: the server secret (--curve-secret) and the key
 * lists.  *out is set even on failure (srv_auth_destroy() it); with no
 * --curve-secret it says CURVE is off (srv_auth_curve() 0) and nothing
 * else is loaded.  Returns 0, or -1 with a message. */
int srv_auth_new(const srv_config *cfg, srv_auth **out, char *err, size_t errlen);

/* 1 if the sockets use CURVE. */
int srv_auth_curve(const srv_auth *a);

/* The server's public key (Z85), "" when CURVE is off. */
const char *srv_auth_server_public(const srv_auth *a);

/* A check of every handshake besides the key's (the connection cap,
 * srv_conns.h), run on the handler's thread: when `side` is readable, and
 * before each answer, drain(arg) reads its events (-1: the context is
 * ending); admit(arg, &open) returns 1 to let the connection in, 0 to
 * refuse it (open: the connections counted, max: the cap, for the log).
 * The handler's thread closes `side` when it ends.  Set before
 * srv_auth_start(); with a gate the handler runs without CURVE too, for
 * sockets in the ZAP domain (srv_auth_zap_domain()). */
typedef struct {
    int (*admit)(void *arg, int *open);
    int (*drain)(void *arg);
    void *arg, *side;
    int max;
} srv_auth_gate;
void srv_auth_set_gate(srv_auth *a, const srv_auth_gate *g);

/* Puts sock (the request socket) in the gate's ZAP domain: its
 * handshakes, NULL ones too, go to the handler and through the gate
 * (the stream socket's do not); call after srv_auth_secure().  0 or -1
 * (errno). */
int srv_auth_zap_domain(void *sock);

/* Binds the ZAP handler in zctx and starts its thread (with CURVE or a
 * gate; a no-op otherwise).  Call before binding the sockets it guards. */
int srv_auth_start(srv_auth *a, void *zctx, char *err, size_t errlen);

/* Makes sock a CURVE server in the "mpmd" ZAP domain (a no-op when CURVE
 * is off). */
int srv_auth_secure(srv_auth *a, void *sock, char *err, size_t errlen);

/* Re-reads the key lists and logs the keys added and removed; the
 * connections of removed keys noted by srv_auth_note_peer() are closed.
 * Main thread only. */
void srv_auth_reload(srv_auth *a);

/* 1 if key (Z85) is in the current lists, or CURVE is off; else 0: a
 * request or subscription of a key removed at the last SIGHUP. */
int srv_auth_key_ok(srv_auth *a, const char *key);

/* Notes the connection message m came in on (ZMQ_SRCFD) as key's, so that
 * a reload that removes key closes it (CURVE only; main thread only). */
void srv_auth_note_peer(srv_auth *a, zmq_msg_t *m, const char *key);

/* A client's quotas (0: no limit). */
typedef struct {
    long long max_jobs, max_particles, max_disk_mb;
} srv_quota;

/* The quotas of owner: the settings on its key's line (in
 * --authorized-keys, else --admin-keys: "KEY max-jobs=N max-particles=N
 * max-disk-mb=N comment", each optional), else cfg's --client-max-jobs,
 * --client-max-particles and --client-max-disk-mb. */
void srv_auth_quota(srv_auth *a, const srv_config *cfg, const char *owner, srv_quota *q);

/* 1 if owner (a Z85 key) is listed in --admin-keys. */
int srv_auth_is_admin(srv_auth *a, const char *owner);

/* Joins the handler thread (after zmq_ctx_term of its context, which ends
 * it) and frees a; nulls the pointer. */
void srv_auth_destroy(srv_auth **a);

#endif
