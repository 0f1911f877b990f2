/* Frame sequences: "shot.####.exr" (Blender's style: the run of '#' is the minimum
 * number of digits, zero padded) and printf's "shot.%04d.exr" / "shot.%d.exr".
 * Only the file-name part is a pattern; '#' and '%' in folder names are literal.
 * Negative frame numbers are not matched. */
#include "cli.h"
#include "os.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

static char *dup_n(const char *s, size_t n)
{
    char *d = malloc(n + 1);
    if (d) {
        memcpy(d, s, n);
        d[n] = '\0';
    }
    return d;
}

void cli_pattern_free(cli_pattern *p)
{
    if (!p)
        return;
    free(p->dir);
    free(p->head);
    free(p->tail);
    free(p->name_head);
    memset(p, 0, sizeof *p);
}

/* Finds a frame spec in name: a run of '#' or "%d" / "%0Nd" / "%Nd". Returns its
 * offset (and length, width) or -1. "%%" is skipped (a literal percent). */
static int find_spec(const char *name, size_t *len, int *width, int *malformed)
{
    *malformed = 0;
    for (size_t i = 0; name[i]; i++) {
        if (name[i] == '#') {
            size_t n = 0;
            while (name[i + n] == '#')
                n++;
            *len = n;
            *width = (int)n;
            return (int)i;
        }
        if (name[i] == '%') {
            if (name[i + 1] == '%') {
                i++;
                continue;
            }
            size_t j = i + 1;
            int w = 0;
            while (name[j] >= '0' && name[j] <= '9' && w < 100)
                w = w * 10 + (name[j++] - '0');
            if (name[j] == 'd') {
                *len = j + 1 - i;
                *width = w;
                return (int)i;
            }
            *malformed = 1; /* "%s", "%x"...: not a frame number */
            return -1;
        }
    }
    return -1;
}

int cli_pattern_parse(const char *path, cli_pattern *out, char *err, size_t err_size)
{
    memset(out, 0, sizeof *out);
    const char *slash = cli_os_last_separator(path);
    const char *name = slash ? slash + 1 : path;
    size_t len = 0;
    int width = 0, malformed = 0;
    int at = find_spec(name, &len, &width, &malformed);
    if (at < 0) {
        if (malformed) {
            snprintf(err, err_size, "'%s': only '#' runs and %%d / %%0Nd are frame patterns", path);
            return -1;
        }
        return 0;
    }
    size_t len2 = 0;
    int width2 = 0;
    if (find_spec(name + at + len, &len2, &width2, &malformed) >= 0 || malformed) {
        snprintf(err, err_size, "'%s' has more than one frame-number pattern", path);
        return -1;
    }
    size_t head_len = (size_t)(name - path) + (size_t)at;
    out->head = dup_n(path, head_len);
    out->tail = strdup(name + at + len);
    out->name_head = dup_n(name, (size_t)at);
    if (!slash)
        out->dir = strdup(".");
    else if (slash == path)
        out->dir = strdup("/");
    else
        out->dir = dup_n(path, (size_t)(slash - path));
    out->width = width;
    if (!out->head || !out->tail || !out->name_head || !out->dir) {
        cli_pattern_free(out);
        snprintf(err, err_size, "out of memory");
        return -1;
    }
    return 1;
}

char *cli_pattern_format(const cli_pattern *p, long frame)
{
    size_t n = strlen(p->head) + strlen(p->tail) + 32;
    char *s = malloc(n);
    if (s)
        snprintf(s, n, "%s%0*ld%s", p->head, p->width, frame, p->tail);
    return s;
}

/* Parses the digits of a directory entry against the pattern: the digits must be
 * what cli_pattern_format() would write for their value. */
static int match_name(const cli_pattern *p, const char *name, long *frame)
{
    size_t hl = strlen(p->name_head), tl = strlen(p->tail), nl = strlen(name);
    if (nl <= hl + tl || strncmp(name, p->name_head, hl) != 0 ||
        strcmp(name + nl - tl, p->tail) != 0)
        return 0;
    const char *d = name + hl;
    size_t dl = nl - hl - tl;
    if (dl > 9)
        return 0;
    long v = 0;
    for (size_t i = 0; i < dl; i++) {
        if (d[i] < '0' || d[i] > '9')
            return 0;
        v = v * 10 + (d[i] - '0');
    }
    /* canonical form: exactly `width` digits, or more without a leading zero */
    if ((int)dl < p->width)
        return 0;
    if ((int)dl > p->width && dl > 1 && d[0] == '0')
        return 0;
    *frame = v;
    return 1;
}

static int by_frame(const void *a, const void *b)
{
    long fa = ((const cli_seq_item *)a)->frame, fb = ((const cli_seq_item *)b)->frame;
    return (fa > fb) - (fa < fb);
}

void cli_seq_free(cli_seq_item *items, int count)
{
    for (int i = 0; i < count; i++)
        free(items[i].path);
    free(items);
}

int cli_pattern_expand(const cli_pattern *p, long first, long last, cli_seq_item **items,
                       int *count)
{
    *items = NULL;
    *count = 0;
    cli_os_dir *dir = cli_os_opendir(p->dir);
    if (!dir)
        return -1;
    cli_seq_item *list = NULL;
    int n = 0, cap = 0;
    const char *entry;
    while ((entry = cli_os_readdir(dir)) != NULL) {
        long frame;
        if (!match_name(p, entry, &frame) || frame < first || frame > last)
            continue;
        if (n == cap) {
            int ncap = cap ? cap * 2 : 64;
            cli_seq_item *grown = realloc(list, (size_t)ncap * sizeof *list);
            if (!grown)
                goto oom;
            list = grown;
            cap = ncap;
        }
        list[n].frame = frame;
        list[n].path = cli_pattern_format(p, frame);
        if (!list[n].path)
            goto oom;
        n++;
    }
    cli_os_closedir(dir);
    if (n > 1)
        qsort(list, (size_t)n, sizeof *list, by_frame);
    *items = list;
    *count = n;
    return 0;
oom:
    cli_os_closedir(dir);
    cli_seq_free(list, n);
    errno = ENOMEM;
    return -1;
}
