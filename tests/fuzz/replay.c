/* Replays a fuzz corpus without libFuzzer: runs the harness it is linked with
 * (LLVMFuzzerTestOneInput) once on every file of the directories given, so that the
 * seeds and the reproducers of every bug the fuzzers found (crash-*) run in every ctest
 * build, the gcc Release one and the ASan+UBSan one, with or without clang. A harness
 * invariant that fails aborts (the test fails); a sanitizer report fails the ASan build.
 * Prints one line per directory. */
#define _POSIX_C_SOURCE 200809L
#include <dirent.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int replay_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) return -1;
    uint8_t *buf = NULL;
    size_t len = 0, cap = 0;
    for (;;) {
        if (len == cap) {
            cap = cap ? 2 * cap : 4096;
            uint8_t *nb = realloc(buf, cap);
            if (!nb) { free(buf); fclose(f); return -1; }
            buf = nb;
        }
        size_t got = fread(buf + len, 1, cap - len, f);
        if (got == 0) break;
        len += got;
    }
    fclose(f);
    /* an exact-size copy, so that ASan sees a read past the input's end */
    uint8_t *exact = malloc(len ? len : 1);
    if (!exact) { free(buf); return -1; }
    if (len) memcpy(exact, buf, len);
    free(buf);
    LLVMFuzzerTestOneInput(exact, len);
    free(exact);
    return 0;
}

int main(int argc, char **argv)
{
    int bad = 0;
    for (int a = 1; a < argc; a++) {
        DIR *d = opendir(argv[a]);
        if (!d) { fprintf(stderr, "replay: cannot open %s\n", argv[a]); bad = 1; continue; }
        int n = 0;
        struct dirent *e;
        char path[4096];
        while ((e = readdir(d))) {
            if (e->d_name[0] == '.') continue;
            snprintf(path, sizeof path, "%s/%s", argv[a], e->d_name);
            struct stat sb;
            if (stat(path, &sb) != 0 || !S_ISREG(sb.st_mode)) continue;
            if (replay_file(path)) { fprintf(stderr, "replay: cannot read %s\n", path); bad = 1; }
            n++;
        }
        closedir(d);
        printf("replayed %d inputs of %s\n", n, argv[a]);
        if (n == 0) bad = 1;
    }
    return bad;
}
