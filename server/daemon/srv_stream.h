/*
 * srv_stream.h - the stream socket's subscriptions and relay (srv_stream.c):
 * which subscriptions the daemon applies, how many it lets the peers hold,
 * and how much it queues for one watcher.  Main thread only.
 */
#ifndef SRV_STREAM_H
#define SRV_STREAM_H

#include <stddef.h>
#include <stdint.h>

#include "srv_config.h"
#include "srv_daemon_int.h"

/* The largest message a stream peer may send (ZMQ_MAXMSGSIZE on the XPUB):
 * a subscription is a 21-byte job topic plus its 1-byte flag, but the
 * handshake comes through the same limit (CURVE's INITIATE command is
 * about 300 bytes).  libzmq drops the connection of a peer whose message
 * is larger as soon as its size is read. */
#define SRV_STREAM_MAX_MSG 512
/* The stream socket's high-water mark per connection, in messages. */
#define SRV_STREAM_HWM 10000

typedef struct srv_stream srv_stream;

/* The stream's bookkeeping for cfg (its limits); NULL when out of memory. */
srv_stream *srv_stream_new(const srv_config *cfg);
void srv_stream_destroy(srv_stream **p);

/* 1 if somebody's subscription to job is applied (a job submitted after
 * its watcher subscribed is watched from its first step). */
int srv_stream_watched(const srv_stream *s, uint64_t job);

/* The stream socket's subscription messages (at most a budget of them a
 * call) and the relay of the workers' stream messages to it (budget
 * frames, 0: until none is left). */
void srv_stream_on_xpub(daemon_t *d);
void srv_stream_relay(daemon_t *d, long budget);
/* Publishes a stream message of a job that the main thread made itself
 * (the Finished of a job cancelled or interrupted while queued); frees it.
 * arg: the daemon_t (a srv_pool_publish_fn). */
void srv_stream_publish(void *arg, uint64_t job, uint8_t *msg, size_t len);

#endif
