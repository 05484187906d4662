/* Generated test meshes: see dk_test_meshes.h. */
#include "dk_test_meshes.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const double PI = 3.14159265358979323846;

void dk_test_mesh_free(dk_test_mesh *m)
{
    if (!m) return;
    free(m->positions);
    free(m->faces);
    memset(m, 0, sizeof *m);
}

/* Allocates both arrays; on failure frees and zeroes. */
static int alloc_mesh(dk_test_mesh *out, int64_t nv, int64_t nf)
{
    memset(out, 0, sizeof *out);
    if (nv < 0 || nf < 0 || nv > INT32_MAX || nf > INT32_MAX / 3) return -1;
    out->positions = malloc(sizeof(double) * 3 * (size_t)(nv ? nv : 1));
    out->faces = malloc(sizeof(dk_index) * 3 * (size_t)(nf ? nf : 1));
    if (!out->positions || !out->faces) {
        dk_test_mesh_free(out);
        return -1;
    }
    out->n_vertices = (dk_index)nv;
    out->n_faces = (dk_index)nf;
    return 0;
}

static void set_tri(dk_index *f, dk_index a, dk_index b, dk_index c)
{
    f[0] = a;
    f[1] = b;
    f[2] = c;
}

/* Deterministic pseudo-random number in [-1, 1] (xorshift on a caller-held state). */
static double jitter_rand(uint64_t *s)
{
    uint64_t x = *s;
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    *s = x;
    return (double)(x >> 11) / (double)(UINT64_C(1) << 53) * 2.0 - 1.0;
}

/* Triangulates an (n+1) x (n+1) vertex grid (vertex (i,j) = j*(n+1)+i) with alternating
 * diagonals, counter-clockwise seen from +z. */
static void grid_faces(int n, dk_index *faces)
{
    dk_index w = (dk_index)n + 1;
    int64_t t = 0;
    for (int j = 0; j < n; j++) {
        for (int i = 0; i < n; i++) {
            dk_index a = j * w + i, b = a + 1, c = a + w + 1, d = a + w;
            if ((i + j) % 2 == 0) {
                set_tri(faces + 3 * t++, a, b, c);
                set_tri(faces + 3 * t++, a, c, d);
            } else {
                set_tri(faces + 3 * t++, a, b, d);
                set_tri(faces + 3 * t++, b, c, d);
            }
        }
    }
}

int dk_test_grid(int n, double size, double jitter, dk_test_mesh *out)
{
    if (!out) return -1;
    memset(out, 0, sizeof *out);
    if (n < 1 || n > 20000) return -1;
    int64_t w = n + 1;
    if (alloc_mesh(out, w * w, 2 * (int64_t)n * n)) return -1;
    double h = size / n;
    uint64_t seed = 0x9E3779B97F4A7C15ull;
    for (int64_t j = 0; j < w; j++) {
        for (int64_t i = 0; i < w; i++) {
            double *p = out->positions + 3 * (j * w + i);
            p[0] = (double)i * h;
            p[1] = (double)j * h;
            p[2] = 0.0;
            if (i > 0 && j > 0 && i < n && j < n) {
                p[0] += jitter * h * jitter_rand(&seed);
                p[1] += jitter * h * jitter_rand(&seed);
            }
        }
    }
    /* exact boundary: the last row/column land exactly on `size` */
    for (int64_t k = 0; k < w; k++) {
        out->positions[3 * (k * w + n) + 0] = size;
        out->positions[3 * (n * w + k) + 1] = size;
    }
    grid_faces(n, out->faces);
    return 0;
}

int dk_test_bumpy_plane(int n, double amplitude, dk_test_mesh *out)
{
    static const double bumps[4][4] = {
        /* cx, cy, sigma, sign */
        {-0.4, -0.3, 0.25, 1.0},
        {0.45, 0.35, 0.2, 1.0},
        {0.3, -0.5, 0.15, -0.7},
        {-0.5, 0.5, 0.3, 0.5},
    };
    if (dk_test_grid(n, 2.0, 0.0, out)) return -1;
    for (dk_index v = 0; v < out->n_vertices; v++) {
        double *p = out->positions + 3 * v;
        p[0] -= 1.0;
        p[1] -= 1.0;
        double z = 0.0;
        for (int b = 0; b < 4; b++) {
            double dx = p[0] - bumps[b][0], dy = p[1] - bumps[b][1], s = bumps[b][2];
            z += bumps[b][3] * exp(-(dx * dx + dy * dy) / (2 * s * s));
        }
        p[2] = amplitude * z;
    }
    return 0;
}

/* Rings of a square tube; returns the ring size. Positions for rings 0..segments. */
static void bar_rings(int segments, int per_side, double hw, double length, double *pos)
{
    int rs = 4 * per_side;
    for (int r = 0; r <= segments; r++) {
        double z = length * r / segments;
        for (int k = 0; k < rs; k++) {
            int side = k / per_side;
            double t = -hw + 2.0 * hw * (k % per_side) / per_side;
            double x, y;
            switch (side) {
            case 0: x = t; y = -hw; break;   /* bottom, going +x */
            case 1: x = hw; y = t; break;    /* right, going +y  */
            case 2: x = -t; y = hw; break;   /* top, going -x    */
            default: x = -hw; y = -t; break; /* left, going -y   */
            }
            double *p = pos + 3 * ((int64_t)r * rs + k);
            p[0] = x;
            p[1] = y;
            p[2] = z;
        }
    }
}

/* Quads between consecutive rings of `rs` vertices (ring winding counter-clockwise seen
 * from +z), outward-facing. Writes 2 * rs * segments triangles. */
static dk_index *ring_strip(int segments, int rs, dk_index *f)
{
    for (int r = 0; r < segments; r++) {
        for (int k = 0; k < rs; k++) {
            dk_index a = r * rs + k, b = r * rs + (k + 1) % rs;
            dk_index c = b + rs, d = a + rs;
            set_tri(f, a, b, c);
            set_tri(f + 3, a, c, d);
            f += 6;
        }
    }
    return f;
}

int dk_test_bar(int segments, int per_side, double half_width, double length,
                dk_test_mesh *out)
{
    if (!out) return -1;
    memset(out, 0, sizeof *out);
    if (segments < 1 || per_side < 1 || segments > 100000 || per_side > 10000) return -1;
    int rs = 4 * per_side;
    if (alloc_mesh(out, (int64_t)(segments + 1) * rs, 2 * (int64_t)rs * segments)) return -1;
    bar_rings(segments, per_side, half_width, length, out->positions);
    ring_strip(segments, rs, out->faces);
    return 0;
}

/* Fan caps over ring 0 (facing -z) and the last ring (facing +z). */
static void caps(int segments, int rs, dk_index c0, dk_index c1, dk_index *f)
{
    dk_index last = segments * rs;
    for (int k = 0; k < rs; k++) {
        dk_index a = k, b = (k + 1) % rs;
        set_tri(f, c0, b, a); /* seen from -z this is counter-clockwise */
        set_tri(f + 3, c1, last + a, last + b);
        f += 6;
    }
}

int dk_test_closed_bar(int segments, int per_side, double half_width, double length,
                       dk_test_mesh *out)
{
    if (!out) return -1;
    memset(out, 0, sizeof *out);
    if (segments < 1 || per_side < 1 || segments > 100000 || per_side > 10000) return -1;
    int rs = 4 * per_side;
    int64_t nr = (int64_t)(segments + 1) * rs;
    if (alloc_mesh(out, nr + 2, 2 * (int64_t)rs * segments + 2 * rs)) return -1;
    bar_rings(segments, per_side, half_width, length, out->positions);
    double *c = out->positions + 3 * nr;
    c[0] = c[1] = c[2] = 0.0;
    c[3] = c[4] = 0.0;
    c[5] = length;
    dk_index *f = ring_strip(segments, rs, out->faces);
    caps(segments, rs, (dk_index)nr, (dk_index)nr + 1, f);
    return 0;
}

int dk_test_cylinder(int around, int rings, double radius, double length, int capped,
                     dk_test_mesh *out)
{
    if (!out) return -1;
    memset(out, 0, sizeof *out);
    if (around < 3 || rings < 1 || around > 100000 || rings > 100000) return -1;
    int64_t nr = (int64_t)(rings + 1) * around;
    int64_t nf = 2 * (int64_t)around * rings + (capped ? 2 * around : 0);
    if (alloc_mesh(out, nr + (capped ? 2 : 0), nf)) return -1;
    for (int r = 0; r <= rings; r++) {
        for (int k = 0; k < around; k++) {
            double a = 2 * PI * k / around;
            double *p = out->positions + 3 * ((int64_t)r * around + k);
            p[0] = radius * cos(a);
            p[1] = radius * sin(a);
            p[2] = length * r / rings;
        }
    }
    dk_index *f = ring_strip(rings, around, out->faces);
    if (capped) {
        double *c = out->positions + 3 * nr;
        c[0] = c[1] = c[2] = 0.0;
        c[3] = c[4] = 0.0;
        c[5] = length;
        caps(rings, around, (dk_index)nr, (dk_index)nr + 1, f);
    }
    return 0;
}

/* ---------------------------------------------------------------- icosphere ------------- */

/* Open-addressing map from an undirected edge to its midpoint vertex. */
typedef struct edge_map {
    uint64_t *keys; /* (min << 32 | max) + 1; 0 = empty */
    dk_index *vals;
    size_t mask;
} edge_map;

static dk_index edge_midpoint(edge_map *m, dk_index a, dk_index b, double *pos, dk_index *nv)
{
    dk_index lo = a < b ? a : b, hi = a < b ? b : a;
    uint64_t key = (((uint64_t)(uint32_t)lo << 32) | (uint32_t)hi) + 1;
    size_t h = (size_t)((key * 0x9E3779B97F4A7C15ull) >> 17) & m->mask;
    while (m->keys[h] && m->keys[h] != key) h = (h + 1) & m->mask;
    if (m->keys[h]) return m->vals[h];
    dk_index v = (*nv)++;
    double *p = pos + 3 * (int64_t)v, *pa = pos + 3 * (int64_t)a, *pb = pos + 3 * (int64_t)b;
    double len = 0;
    for (int i = 0; i < 3; i++) {
        p[i] = 0.5 * (pa[i] + pb[i]);
        len += p[i] * p[i];
    }
    len = sqrt(len);
    for (int i = 0; i < 3; i++) p[i] /= len; /* unit sphere while subdividing */
    m->keys[h] = key;
    m->vals[h] = v;
    return v;
}

int dk_test_icosphere(int level, double radius, dk_test_mesh *out)
{
    if (!out) return -1;
    memset(out, 0, sizeof *out);
    if (level < 0 || level > 10) return -1;
    int64_t nf = 20, nv = 12;
    for (int l = 0; l < level; l++) {
        nv += nf * 3 / 2;
        nf *= 4;
    }
    if (alloc_mesh(out, nv, nf)) return -1;
    dk_index *tmp = malloc(sizeof(dk_index) * 3 * (size_t)nf);
    if (!tmp) {
        dk_test_mesh_free(out);
        return -1;
    }
    const double t = (1.0 + sqrt(5.0)) / 2.0;
    const double base[12][3] = {{-1, t, 0}, {1, t, 0},   {-1, -t, 0}, {1, -t, 0},
                                {0, -1, t}, {0, 1, t},   {0, -1, -t}, {0, 1, -t},
                                {t, 0, -1}, {t, 0, 1},   {-t, 0, -1}, {-t, 0, 1}};
    static const dk_index ico[20][3] = {
        {0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
        {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
        {3, 8, 9},  {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
    double n0 = sqrt(1 + t * t);
    for (int v = 0; v < 12; v++)
        for (int i = 0; i < 3; i++) out->positions[3 * v + i] = base[v][i] / n0;
    memcpy(out->faces, ico, sizeof ico);
    dk_index cur_v = 12;
    int64_t cur_f = 20;
    for (int l = 0; l < level; l++) {
        size_t cap = 1;
        while (cap < (size_t)(cur_f * 3)) cap <<= 1; /* >= 2x the edge count */
        edge_map m = {calloc(cap, sizeof(uint64_t)), malloc(cap * sizeof(dk_index)), cap - 1};
        if (!m.keys || !m.vals) {
            free(m.keys);
            free(m.vals);
            free(tmp);
            dk_test_mesh_free(out);
            return -1;
        }
        for (int64_t f = 0; f < cur_f; f++) {
            dk_index a = out->faces[3 * f], b = out->faces[3 * f + 1], c = out->faces[3 * f + 2];
            dk_index ab = edge_midpoint(&m, a, b, out->positions, &cur_v);
            dk_index bc = edge_midpoint(&m, b, c, out->positions, &cur_v);
            dk_index ca = edge_midpoint(&m, c, a, out->positions, &cur_v);
            set_tri(tmp + 12 * f, a, ab, ca);
            set_tri(tmp + 12 * f + 3, b, bc, ab);
            set_tri(tmp + 12 * f + 6, c, ca, bc);
            set_tri(tmp + 12 * f + 9, ab, bc, ca);
        }
        free(m.keys);
        free(m.vals);
        cur_f *= 4;
        memcpy(out->faces, tmp, sizeof(dk_index) * 3 * (size_t)cur_f);
    }
    free(tmp);
    /* project exactly onto the sphere of the requested radius */
    for (int64_t v = 0; v < nv; v++) {
        double *p = out->positions + 3 * v;
        double len = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        for (int i = 0; i < 3; i++) p[i] = p[i] / len * radius;
    }
    return 0;
}

int dk_test_uv_sphere(int around, int bands, double radius, dk_test_mesh *out)
{
    if (!out) return -1;
    memset(out, 0, sizeof *out);
    if (around < 3 || bands < 2 || around > 100000 || bands > 100000) return -1;
    int64_t nv = (int64_t)around * (bands - 1) + 2;
    int64_t nf = 2 * (int64_t)around * (bands - 1);
    if (alloc_mesh(out, nv, nf)) return -1;
    double *p = out->positions;
    p[0] = p[1] = 0.0;
    p[2] = -radius;
    for (int b = 1; b < bands; b++) {
        double th = PI * b / bands - PI / 2; /* latitude */
        for (int k = 0; k < around; k++) {
            double a = 2 * PI * k / around;
            double *q = p + 3 * (1 + (int64_t)(b - 1) * around + k);
            q[0] = radius * cos(th) * cos(a);
            q[1] = radius * cos(th) * sin(a);
            q[2] = radius * sin(th);
        }
    }
    double *np = p + 3 * (nv - 1);
    np[0] = np[1] = 0.0;
    np[2] = radius;
    dk_index *f = out->faces;
    dk_index north = (dk_index)nv - 1;
    for (int k = 0; k < around; k++) {
        set_tri(f, 0, 1 + (k + 1) % around, 1 + k);
        f += 3;
    }
    for (int b = 0; b < bands - 2; b++) {
        for (int k = 0; k < around; k++) {
            dk_index a = 1 + b * around + k, c = 1 + b * around + (k + 1) % around;
            set_tri(f, a, c, c + around);
            set_tri(f + 3, a, c + around, a + around);
            f += 6;
        }
    }
    dk_index top = 1 + (bands - 2) * around;
    for (int k = 0; k < around; k++) {
        set_tri(f, north, top + k, top + (k + 1) % around);
        f += 3;
    }
    return 0;
}

dk_mesh *dk_test_mesh_build(const dk_test_mesh *m)
{
    dk_mesh *mesh = NULL;
    dk_error err = {0};
    if (!m) return NULL;
    if (dk_mesh_create(m->positions, m->n_vertices, m->faces, m->n_faces, &mesh, &err)) {
        fprintf(stderr, "dk_test_mesh_build: %s\n", err.message);
        return NULL;
    }
    return mesh;
}

char *dk_test_read_file(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    char *buf = NULL;
    size_t len = 0, cap = 0;
    for (;;) {
        if (cap - len < 4096) {
            size_t ncap = cap ? cap * 2 : 65536;
            char *nb = realloc(buf, ncap);
            if (!nb) {
                free(buf);
                fclose(f);
                return NULL;
            }
            buf = nb;
            cap = ncap;
        }
        size_t got = fread(buf + len, 1, cap - len - 1, f);
        len += got;
        if (got == 0) break;
    }
    int bad = ferror(f);
    fclose(f);
    if (bad) {
        free(buf);
        return NULL;
    }
    buf[len] = '\0';
    if (size) *size = len;
    return buf;
}

int dk_test_write_file(const char *path, const char *text)
{
    FILE *f = fopen(path, "wb");
    if (!f) return -1;
    size_t n = strlen(text);
    int bad = fwrite(text, 1, n, f) != n;
    bad |= fclose(f) != 0;
    return bad ? -1 : 0;
}

const char *dk_test_shared_mesh_path(const char *shared_dir, const char *name, char *buf,
                                     size_t buf_size)
{
    int n = snprintf(buf, buf_size, "%s/meshes/%s", shared_dir, name);
    if (n < 0 || (size_t)n >= buf_size) return NULL;
    return buf;
}
