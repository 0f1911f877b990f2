/* Progress: on a terminal, one line redrawn with '\r' (frame i/N, a bar over the
 * whole job, the library's stage, ETA); elsewhere (logs, pipes) one summary line per
 * frame on stdout: "frame 12: 0.41 s, out.0012.exr". */
#include "cli.h"

#include <string.h>

static cli_progress *g_active; /* the bar on screen, erased before messages */

void cli_progress_init(cli_progress *p, int total, int tty, int summaries)
{
    memset(p, 0, sizeof *p);
    p->tty = tty;
    p->summaries = summaries;
    p->total = total > 0 ? total : 1;
    p->start = cli_now();
    p->stage = "";
}

void cli_progress_clear_line(void)
{
    if (g_active && g_active->drawn) {
        fputs("\r\033[K", stderr);
        fflush(stderr);
        g_active->drawn = 0;
    }
}

static void format_duration(char *buf, size_t size, double s)
{
    if (s < 0)
        s = 0;
    long t = (long)(s + 0.5);
    if (t >= 3600)
        snprintf(buf, size, "%ld:%02ld:%02ld", t / 3600, (t / 60) % 60, t % 60);
    else
        snprintf(buf, size, "%ld:%02ld", t / 60, t % 60);
}

static void draw(cli_progress *p)
{
    enum { BAR = 24 };
    double done = ((double)p->done + p->fraction) / (double)p->total;
    if (done > 1)
        done = 1;
    double elapsed = cli_now() - p->start;
    char eta[32] = "--:--";
    if (done > 0.005)
        format_duration(eta, sizeof eta, elapsed * (1.0 - done) / done);
    int fill = (int)(done * BAR + 0.5);
    char bar[BAR + 1];
    for (int i = 0; i < BAR; i++)
        bar[i] = i < fill ? '#' : '-';
    bar[BAR] = '\0';
    int index = p->done + 1 > p->total ? p->total : p->done + 1;
    char number[32] = "";
    if (p->show_number)
        snprintf(number, sizeof number, " (#%ld)", p->frame);
    fprintf(stderr, "\r\033[Kframe %d/%d%s [%s] %3d%%  ETA %s  %.48s", index, p->total, number, bar,
            (int)(done * 100.0), eta, p->stage ? p->stage : "");
    fflush(stderr);
    p->drawn = 1;
    p->last_draw = cli_now();
    g_active = p;
}

void cli_progress_frame_begin(cli_progress *p, long frame, int show_number)
{
    p->frame = frame;
    p->show_number = show_number;
    p->fraction = 0;
    p->phase = 0;
    p->stage = "read";
    if (p->tty)
        draw(p);
}

void cli_progress_phase(cli_progress *p, int phase, const char *stage)
{
    p->phase = phase;
    p->stage = stage;
    cli_progress_callback(p, stage, 0.0);
}

int cli_progress_callback(void *user, const char *stage, double fraction)
{
    /* The library reports each call's own 0..1 (read, effects, write): map them onto
     * one frame as 0-15 %, 15-90 %, 90-100 %. */
    static const double base[3] = { 0.0, 0.15, 0.90 }, span[3] = { 0.15, 0.75, 0.10 };
    cli_progress *p = user;
    if (p && p->tty) {
        int ph = p->phase < 0 ? 0 : p->phase > 2 ? 2 : p->phase;
        fraction = fraction < 0 ? 0 : fraction > 1 ? 1 : fraction;
        p->stage = stage;
        p->fraction = base[ph] + span[ph] * fraction;
        if (cli_now() - p->last_draw > 0.1)
            draw(p);
    }
    return cli_interrupted();
}

void cli_progress_frame_end(cli_progress *p, double seconds, const char *out_path)
{
    p->done++;
    p->fraction = 0;
    p->stage = "";
    if (p->summaries) {
        cli_progress_clear_line();
        printf("frame %ld: %.2f s, %s\n", p->frame, seconds, out_path);
        fflush(stdout);
    }
    /* the bar is redrawn by the next frame_begin, or replaced by finish */
}

void cli_progress_finish(cli_progress *p)
{
    if (p->tty && p->drawn && !p->show_number) { /* one file: just erase the bar */
        cli_progress_clear_line();
    } else if (p->tty && p->drawn) {
        char total[32];
        format_duration(total, sizeof total, cli_now() - p->start);
        fprintf(stderr, "\r\033[K%d/%d frames in %s\n", p->done, p->total, total);
        fflush(stderr);
        p->drawn = 0;
    }
    if (g_active == p)
        g_active = NULL;
}
