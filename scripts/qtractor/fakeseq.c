/* fakeseq.c - LD_PRELOAD stand-in for the ALSA sequencer (no /dev/snd/seq in
 * this container).  Only the snd_seq_* calls that need a live kernel client
 * are replaced; they succeed as no-ops so Qtractor's MIDI engine can start.
 * Qtractor feeds MIDI-track plugins directly (qtractorMidiManager::queued),
 * not through ALSA, so the plugin path under test is untouched. */
#include <alsa/asoundlib.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

struct fake_seq { int pipefd[2]; int next_port; int next_queue; };
static int g_next_client = 128;
static int g_verbose = -1;
static void note(const char *fn) {
	if (g_verbose < 0) g_verbose = getenv("FAKESEQ_VERBOSE") ? 1 : 0;
	if (g_verbose) fprintf(stderr, "[fakeseq] %s\n", fn);
}
#define F(h) ((struct fake_seq *)(h))

int snd_seq_open(snd_seq_t **handle, const char *name, int streams, int mode) {
	struct fake_seq *s = calloc(1, sizeof *s);
	(void)streams; (void)mode;
	fprintf(stderr, "[fakeseq] snd_seq_open(\"%s\") -> fake client %d\n", name ? name : "", g_next_client);
	if (pipe(s->pipefd) < 0) { free(s); return -errno; }
	s->next_port = 0; s->next_queue = 0;
	*handle = (snd_seq_t *)s;
	return 0;
}
int snd_seq_close(snd_seq_t *h) { note(__func__); close(F(h)->pipefd[0]); close(F(h)->pipefd[1]); free(h); return 0; }
int snd_seq_client_id(snd_seq_t *h) { (void)h; return 128; }
int snd_seq_alloc_queue(snd_seq_t *h) { note(__func__); return F(h)->next_queue++; }
int snd_seq_free_queue(snd_seq_t *h, int q) { (void)h; (void)q; return 0; }
int snd_seq_set_client_name(snd_seq_t *h, const char *n) { (void)h; fprintf(stderr, "[fakeseq] client name \"%s\"\n", n); return 0; }
int snd_seq_create_simple_port(snd_seq_t *h, const char *n, unsigned int c, unsigned int t) {
	(void)c; (void)t; fprintf(stderr, "[fakeseq] port %d \"%s\"\n", F(h)->next_port, n); return F(h)->next_port++; }
int snd_seq_delete_simple_port(snd_seq_t *h, int p) { (void)h; (void)p; return 0; }
int snd_seq_control_queue(snd_seq_t *h, int q, int type, int value, snd_seq_event_t *ev) { (void)h; (void)q; (void)type; (void)value; (void)ev; return 0; }
int snd_seq_drain_output(snd_seq_t *h) { (void)h; return 0; }
int snd_seq_drop_input(snd_seq_t *h) { (void)h; return 0; }
int snd_seq_drop_output(snd_seq_t *h) { (void)h; return 0; }
int snd_seq_event_input(snd_seq_t *h, snd_seq_event_t **ev) { (void)h; if (ev) *ev = NULL; return -EAGAIN; }
int snd_seq_event_input_pending(snd_seq_t *h, int f) { (void)h; (void)f; return 0; }
int snd_seq_event_output(snd_seq_t *h, snd_seq_event_t *ev) { (void)h; (void)ev; return 0; }
int snd_seq_event_output_direct(snd_seq_t *h, snd_seq_event_t *ev) { (void)h; (void)ev; return 0; }
int snd_seq_get_any_client_info(snd_seq_t *h, int c, snd_seq_client_info_t *i) { (void)h; (void)c; (void)i; return -ENOENT; }
int snd_seq_get_any_port_info(snd_seq_t *h, int c, int p, snd_seq_port_info_t *i) { (void)h; (void)c; (void)p; (void)i; return -ENOENT; }
int snd_seq_get_port_info(snd_seq_t *h, int p, snd_seq_port_info_t *i) { (void)h; (void)p; (void)i; return 0; }
int snd_seq_set_port_info(snd_seq_t *h, int p, snd_seq_port_info_t *i) { (void)h; (void)p; (void)i; return 0; }
int snd_seq_get_queue_status(snd_seq_t *h, int q, snd_seq_queue_status_t *s) { (void)h; (void)q; (void)s; return -ENODEV; }
int snd_seq_get_queue_tempo(snd_seq_t *h, int q, snd_seq_queue_tempo_t *t) { (void)h; (void)q; (void)t; return 0; }
int snd_seq_set_queue_tempo(snd_seq_t *h, int q, snd_seq_queue_tempo_t *t) { (void)h; (void)q; (void)t; return 0; }
int snd_seq_set_queue_timer(snd_seq_t *h, int q, snd_seq_queue_timer_t *t) { (void)h; (void)q; (void)t; return 0; }
int snd_seq_poll_descriptors_count(snd_seq_t *h, short ev) { (void)h; (void)ev; return 1; }
int snd_seq_poll_descriptors(snd_seq_t *h, struct pollfd *pfds, unsigned int space, short ev) {
	if (space < 1) return 0; pfds[0].fd = F(h)->pipefd[0]; pfds[0].events = ev; pfds[0].revents = 0; return 1; }
int snd_seq_query_next_client(snd_seq_t *h, snd_seq_client_info_t *i) { (void)h; (void)i; return -ENOENT; }
int snd_seq_query_next_port(snd_seq_t *h, snd_seq_port_info_t *i) { (void)h; (void)i; return -ENOENT; }
int snd_seq_query_port_subscribers(snd_seq_t *h, snd_seq_query_subscribe_t *q) { (void)h; (void)q; return -ENOENT; }
int snd_seq_remove_events(snd_seq_t *h, snd_seq_remove_events_t *r) { (void)h; (void)r; return 0; }
int snd_seq_subscribe_port(snd_seq_t *h, snd_seq_port_subscribe_t *s) { (void)h; (void)s; return 0; }
int snd_seq_unsubscribe_port(snd_seq_t *h, snd_seq_port_subscribe_t *s) { (void)h; (void)s; return 0; }
