/* Mesh file reading (OBJ, OFF, PLY) and OBJ writing: see dk_io.h.
 *
 * The file is checked first (a regular file, after following symlinks, of at most
 * DK_MESH_FILE_MAX_BYTES), then read whole into one NUL-terminated buffer and parsed in
 * place; output arrays grow by doubling. Text parsing uses strtod/strtol, which stop at
 * whitespace, so the buffer is never modified.
 */
#define _POSIX_C_SOURCE 200809L
#include "dk_io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------ growable arrays ------ */

typedef struct builder {
    double *pos;
    int64_t nv, cap_v;
    dk_index *sizes;
    int64_t np, cap_p;
    dk_index *idx;
    int64_t ni, cap_i;
} builder;

static int grow(void **p, int64_t *cap, int64_t need, size_t elem)
{
    if (need <= *cap) return 0;
    int64_t c = *cap ? *cap : 1024;
    while (c < need) c *= 2;
    void *q = realloc(*p, (size_t)c * elem);
    if (!q) return -1;
    *p = q;
    *cap = c;
    return 0;
}

static int push_vertex(builder *b, double x, double y, double z)
{
    if (b->nv >= INT32_MAX) return -1;
    if (grow((void **)&b->pos, &b->cap_v, 3 * (b->nv + 1), sizeof(double))) return -1;
    b->pos[3 * b->nv] = x;
    b->pos[3 * b->nv + 1] = y;
    b->pos[3 * b->nv + 2] = z;
    b->nv++;
    return 0;
}

static int push_index(builder *b, dk_index i)
{
    if (grow((void **)&b->idx, &b->cap_i, b->ni + 1, sizeof(dk_index))) return -1;
    b->idx[b->ni++] = i;
    return 0;
}

static int push_size(builder *b, dk_index k)
{
    if (b->np >= INT32_MAX) return -1;
    if (grow((void **)&b->sizes, &b->cap_p, b->np + 1, sizeof(dk_index))) return -1;
    b->sizes[b->np++] = k;
    return 0;
}

static void builder_free(builder *b)
{
    free(b->pos);
    free(b->sizes);
    free(b->idx);
    memset(b, 0, sizeof *b);
}

/* Hands the arrays over (allocating empty ones where needed). */
static dk_status builder_finish(builder *b, dk_mesh_file *out, const char *name, dk_error *err)
{
    if (grow((void **)&b->pos, &b->cap_v, 3, sizeof(double)) ||
        grow((void **)&b->sizes, &b->cap_p, 1, sizeof(dk_index)) ||
        grow((void **)&b->idx, &b->cap_i, 1, sizeof(dk_index))) {
        builder_free(b);
        return dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", name);
    }
    out->positions = b->pos;
    out->n_vertices = (dk_index)b->nv;
    out->face_sizes = b->sizes;
    out->n_polygons = (dk_index)b->np;
    out->indices = b->idx;
    out->n_indices = b->ni;
    memset(b, 0, sizeof *b);
    return DK_OK;
}

#define OOM(name) dk_error_set(err, DK_ERR_OUT_OF_MEMORY, "%s: out of memory", name)

/* ------------------------------------------------------------------ text helpers -------- */

static const char *skip_blanks(const char *s)
{
    while (*s == ' ' || *s == '\t' || *s == '\r' || *s == '\f' || *s == '\v') s++;
    return s;
}

static const char *next_line(const char *s)
{
    while (*s && *s != '\n') s++;
    return *s ? s + 1 : s;
}

/* Parses a finite double at s; returns the end or NULL. Never reads past the line. */
static const char *parse_double(const char *s, double *out)
{
    s = skip_blanks(s);
    if (!*s || *s == '\n') return NULL;
    char *end;
    *out = strtod(s, &end);
    if (end == s || !isfinite(*out)) return NULL;
    return end;
}

static const char *parse_long(const char *s, long long *out)
{
    s = skip_blanks(s);
    if (!*s || *s == '\n') return NULL;
    char *end;
    errno = 0;
    *out = strtoll(s, &end, 10);
    if (end == s || errno) return NULL;
    return end;
}

static int at_line_end(const char *s)
{
    s = skip_blanks(s);
    return !*s || *s == '\n' || *s == '#';
}

/* ------------------------------------------------------------------ OBJ ------------------ */

/* Whether the line at t is a vertex statement `v x y z`. */
static int is_obj_vertex(const char *t)
{
    return t[0] == 'v' && (t[1] == ' ' || t[1] == '\t');
}

static dk_status read_obj(const char *buf, const char *name, dk_mesh_file *out, dk_error *err)
{
    builder b = {0};
    long long line = 0, file_nv = 0;
    /* The file's vertex count first: a positive face index refers to the file's vertices
     * (some writers put faces before vertices), a negative one to those read so far. */
    for (const char *s = buf; *s; s = next_line(s))
        if (is_obj_vertex(skip_blanks(s)))
            file_nv++;
    for (const char *s = buf; *s; s = next_line(s)) {
        line++;
        const char *t = skip_blanks(s);
        if (t[0] == 'v' && (t[1] == ' ' || t[1] == '\t')) {
            double x, y, z;
            const char *q = parse_double(t + 1, &x);
            if (q) q = parse_double(q, &y);
            if (q) q = parse_double(q, &z);
            if (!q) {
                builder_free(&b);
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "%s line %lld: a vertex needs three finite numbers", name,
                                    line);
            }
            if (push_vertex(&b, x, y, z)) {
                builder_free(&b);
                return OOM(name);
            }
        } else if (t[0] == 'f' && (t[1] == ' ' || t[1] == '\t')) {
            const char *q = t + 1;
            dk_index k = 0;
            while (!at_line_end(q)) {
                long long v;
                const char *e = parse_long(q, &v);
                if (!e || (*e && !isspace((unsigned char)*e) && *e != '/')) {
                    builder_free(&b);
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "%s line %lld: malformed face corner %d", name, line,
                                        (int)k);
                }
                long long resolved = v > 0 ? v - 1 : b.nv + v;
                if (v == 0 || resolved < 0 || (v > 0 && resolved >= file_nv)) {
                    const long long so_far = b.nv; /* builder_free zeroes it */
                    builder_free(&b);
                    if (v < 0)
                        return dk_error_set(err, DK_ERR_INDEX,
                                            "%s line %lld: relative face index %lld reaches "
                                            "before the first vertex (%lld vertices so far)",
                                            name, line, v, so_far);
                    return dk_error_set(err, DK_ERR_INDEX,
                                        "%s line %lld: face index %lld is out of range "
                                        "[1, %lld] (the file has %lld vertices)",
                                        name, line, v, file_nv, file_nv);
                }
                if (push_index(&b, (dk_index)resolved)) {
                    builder_free(&b);
                    return OOM(name);
                }
                k++;
                while (*e && !isspace((unsigned char)*e)) e++; /* skip /t/n */
                q = e;
            }
            if (k < 3) {
                builder_free(&b);
                return dk_error_set(err, DK_ERR_TOPOLOGY,
                                    "%s line %lld: a face needs at least 3 corners, got %d",
                                    name, line, (int)k);
            }
            if (push_size(&b, k)) {
                builder_free(&b);
                return OOM(name);
            }
        }
    }
    return builder_finish(&b, out, name, err);
}

/* ------------------------------------------------------------------ OFF ------------------ */

/* Advances to the next line with content (skipping blank and comment lines). */
static const char *content_line(const char *s, long long *line)
{
    while (*s) {
        const char *t = skip_blanks(s);
        if (*t && *t != '\n' && *t != '#') return t;
        s = next_line(s);
        (*line)++;
    }
    return s;
}

static dk_status read_off(const char *buf, const char *name, dk_mesh_file *out, dk_error *err)
{
    builder b = {0};
    long long line = 1, nv, nf, ne;
    const char *s = content_line(buf, &line);
    const char *h = s;
    while (*h && isalpha((unsigned char)*h)) h++;
    if (h - s < 3 || strncmp(h - 3, "OFF", 3) != 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s line %lld: expected an OFF header",
                            name, line);
    const char *q = h;
    if (at_line_end(q)) {
        s = next_line(s);
        line++;
        q = content_line(s, &line);
    }
    q = parse_long(q, &nv);
    if (q) q = parse_long(q, &nf);
    if (q && !at_line_end(q)) q = parse_long(q, &ne);
    if (!q || nv < 0 || nf < 0 || nv > INT32_MAX || nf > INT32_MAX)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s line %lld: expected vertex and face counts", name, line);
    s = next_line(q);
    line++;
    for (long long v = 0; v < nv; v++) {
        s = content_line(s, &line);
        double x, y, z;
        const char *r = parse_double(s, &x);
        if (r) r = parse_double(r, &y);
        if (r) r = parse_double(r, &z);
        if (!r) {
            builder_free(&b);
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s line %lld: vertex %lld needs three finite numbers%s", name,
                                line, v, *s ? "" : " (file ends early)");
        }
        if (push_vertex(&b, x, y, z)) {
            builder_free(&b);
            return OOM(name);
        }
        s = next_line(r);
        line++;
    }
    for (long long f = 0; f < nf; f++) {
        s = content_line(s, &line);
        long long k;
        const char *r = parse_long(s, &k);
        if (!r) {
            builder_free(&b);
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s line %lld: face %lld: expected a corner count%s", name,
                                line, f, *s ? "" : " (file ends early)");
        }
        if (k < 3 || k > INT32_MAX) {
            builder_free(&b);
            return dk_error_set(err, DK_ERR_TOPOLOGY,
                                "%s line %lld: face %lld has %lld corners; at least 3 are "
                                "needed",
                                name, line, f, k);
        }
        for (long long c = 0; c < k; c++) {
            long long v;
            r = parse_long(r, &v);
            if (!r) {
                builder_free(&b);
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "%s line %lld: face %lld: expected %lld indices", name,
                                    line, f, k);
            }
            if (v < 0 || v >= nv) {
                builder_free(&b);
                return dk_error_set(err, DK_ERR_INDEX,
                                    "%s line %lld: face %lld index %lld is out of range "
                                    "[0, %lld]",
                                    name, line, f, v, nv - 1);
            }
            if (push_index(&b, (dk_index)v)) {
                builder_free(&b);
                return OOM(name);
            }
        }
        if (push_size(&b, (dk_index)k)) {
            builder_free(&b);
            return OOM(name);
        }
        s = next_line(r);
        line++;
    }
    return builder_finish(&b, out, name, err);
}

/* ------------------------------------------------------------------ PLY ------------------ */

enum { T_NONE, T_I8, T_U8, T_I16, T_U16, T_I32, T_U32, T_F32, T_F64 };

static int ply_type(const char *s, size_t n)
{
    static const struct {
        const char *name;
        int type;
    } names[] = {{"char", T_I8},    {"int8", T_I8},     {"uchar", T_U8},   {"uint8", T_U8},
                 {"short", T_I16},  {"int16", T_I16},   {"ushort", T_U16}, {"uint16", T_U16},
                 {"int", T_I32},    {"int32", T_I32},   {"uint", T_U32},   {"uint32", T_U32},
                 {"float", T_F32},  {"float32", T_F32}, {"double", T_F64}, {"float64", T_F64}};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (strlen(names[i].name) == n && strncmp(names[i].name, s, n) == 0)
            return names[i].type;
    return T_NONE;
}

static size_t type_size(int t)
{
    static const size_t sz[] = {0, 1, 1, 2, 2, 4, 4, 4, 8};
    return sz[t];
}

#define PLY_MAX_PROPS 32
#define PLY_MAX_ELEMS 16

typedef struct ply_prop {
    int type;       /* value type (list item type for lists) */
    int count_type; /* T_NONE for a scalar */
    int role;       /* 0 other, 1..3 x/y/z, 4 face indices */
} ply_prop;

typedef struct ply_elem {
    int kind; /* 0 other, 1 vertex, 2 face */
    long long count;
    int n_props;
    ply_prop props[PLY_MAX_PROPS];
} ply_elem;

/* Reads the next value of type t: binary from *p (bounded by end) or ascii token. */
static int ply_value(const char **p, const char *end, int binary, int t, double *out,
                     long long *line)
{
    if (binary) {
        size_t n = type_size(t);
        if ((size_t)(end - *p) < n) return -1;
        const unsigned char *u = (const unsigned char *)*p;
        switch (t) {
        case T_I8: *out = (int8_t)u[0]; break;
        case T_U8: *out = u[0]; break;
        case T_I16: { int16_t v; memcpy(&v, u, 2); *out = v; break; }
        case T_U16: { uint16_t v; memcpy(&v, u, 2); *out = v; break; }
        case T_I32: { int32_t v; memcpy(&v, u, 4); *out = v; break; }
        case T_U32: { uint32_t v; memcpy(&v, u, 4); *out = v; break; }
        case T_F32: { float v; memcpy(&v, u, 4); *out = v; break; }
        default: { double v; memcpy(&v, u, 8); *out = v; break; }
        }
        *p += n;
        return 0;
    }
    /* ascii: whitespace (newlines included) separates tokens; count lines for messages */
    const char *s = *p;
    while (*s && isspace((unsigned char)*s)) {
        if (*s == '\n') (*line)++;
        s++;
    }
    if (!*s) return -1;
    char *e;
    *out = strtod(s, &e);
    if (e == s) return -1;
    *p = e;
    return 0;
}

/* " line N" for ascii data, "" for binary (where messages name the element instead). */
static const char *ply_where(char *buf, int binary, long long line)
{
    buf[0] = '\0';
    if (!binary) snprintf(buf, 48, " line %lld", line);
    return buf;
}

static dk_status read_ply(const char *buf, size_t size, const char *name, dk_mesh_file *out,
                          dk_error *err)
{
    ply_elem elems[PLY_MAX_ELEMS];
    int n_elems = 0, binary = -1;
    long long line = 1;
    const char *s = buf, *end = buf + size;
    if (strncmp(s, "ply", 3) != 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s line 1: expected 'ply'", name);
    s = next_line(s);
    for (;;) {
        line++;
        if (!*s || s >= end)
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s: header ends without end_header", name);
        const char *t = skip_blanks(s);
        const char *w = t;
        while (*w && !isspace((unsigned char)*w)) w++;
        size_t wl = (size_t)(w - t);
        if (wl == 10 && strncmp(t, "end_header", 10) == 0) {
            s = next_line(s);
            break;
        }
        if (wl == 6 && strncmp(t, "format", 6) == 0) {
            const char *f = skip_blanks(w);
            if (strncmp(f, "ascii", 5) == 0)
                binary = 0;
            else if (strncmp(f, "binary_little_endian", 20) == 0)
                binary = 1;
            else
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "%s line %lld: unsupported PLY format (only ascii and "
                                    "binary_little_endian)",
                                    name, line);
        } else if (wl == 7 && strncmp(t, "element", 7) == 0) {
            if (n_elems == PLY_MAX_ELEMS)
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "%s line %lld: more than %d elements", name, line,
                                    PLY_MAX_ELEMS);
            ply_elem *e = &elems[n_elems++];
            memset(e, 0, sizeof *e);
            const char *en = skip_blanks(w), *ee = en;
            while (*ee && !isspace((unsigned char)*ee)) ee++;
            if (ee - en == 6 && strncmp(en, "vertex", 6) == 0) e->kind = 1;
            if (ee - en == 4 && strncmp(en, "face", 4) == 0) e->kind = 2;
            if (!parse_long(ee, &e->count) || e->count < 0 || e->count > INT32_MAX)
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "%s line %lld: bad element count", name, line);
        } else if (wl == 8 && strncmp(t, "property", 8) == 0) {
            if (n_elems == 0 || elems[n_elems - 1].n_props == PLY_MAX_PROPS)
                return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                    "%s line %lld: property outside an element or too many",
                                    name, line);
            ply_elem *e = &elems[n_elems - 1];
            ply_prop *p = &e->props[e->n_props++];
            memset(p, 0, sizeof *p);
            const char *a = skip_blanks(w), *ae = a;
            while (*ae && !isspace((unsigned char)*ae)) ae++;
            if (ae - a == 4 && strncmp(a, "list", 4) == 0) {
                const char *c = skip_blanks(ae), *ce = c;
                while (*ce && !isspace((unsigned char)*ce)) ce++;
                const char *v = skip_blanks(ce), *ve = v;
                while (*ve && !isspace((unsigned char)*ve)) ve++;
                p->count_type = ply_type(c, (size_t)(ce - c));
                p->type = ply_type(v, (size_t)(ve - v));
                ae = ve;
                if (p->count_type == T_NONE || p->type == T_NONE)
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "%s line %lld: unknown list property type", name, line);
            } else {
                p->type = ply_type(a, (size_t)(ae - a));
                if (p->type == T_NONE)
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "%s line %lld: unknown property type", name, line);
            }
            const char *pn = skip_blanks(ae), *pe = pn;
            while (*pe && !isspace((unsigned char)*pe)) pe++;
            size_t pl = (size_t)(pe - pn);
            if (e->kind == 1 && !p->count_type && pl == 1 && *pn >= 'x' && *pn <= 'z')
                p->role = 1 + (*pn - 'x');
            if (e->kind == 2 && p->count_type &&
                ((pl == 14 && strncmp(pn, "vertex_indices", 14) == 0) ||
                 (pl == 12 && strncmp(pn, "vertex_index", 12) == 0)))
                p->role = 4;
        }
        s = next_line(s);
    }
    if (binary < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: PLY header has no format line",
                            name);
    long long nv = 0;
    int have_xyz = 0, have_faces = 0;
    for (int i = 0; i < n_elems; i++) {
        if (elems[i].kind == 1) {
            nv = elems[i].count;
            for (int k = 0; k < elems[i].n_props; k++)
                if (elems[i].props[k].role >= 1 && elems[i].props[k].role <= 3)
                    have_xyz |= 1 << (elems[i].props[k].role - 1);
        }
        if (elems[i].kind == 2)
            for (int k = 0; k < elems[i].n_props; k++)
                if (elems[i].props[k].role == 4) have_faces = 1;
    }
    if (have_xyz != 7)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: PLY vertex element lacks x, y or z", name);
    (void)have_faces; /* a point cloud is allowed */
    builder b = {0};
    const char *p = s;
    char where[48] = "";
    line++; /* the first data line (ascii line numbers are counted by ply_value) */
    for (int i = 0; i < n_elems; i++) {
        ply_elem *e = &elems[i];
        /* An element without properties holds no data: its items take no bytes, and
         * walking through a count of 2^31 of them did nothing for seconds (found by
         * fuzz_mesh_ply; a header may list 16 such elements). */
        if (e->n_props == 0) continue;
        for (long long item = 0; item < e->count; item++) {
            double xyz[3] = {0, 0, 0};
            for (int k = 0; k < e->n_props; k++) {
                ply_prop *pr = &e->props[k];
                double v;
                if (!pr->count_type) {
                    if (ply_value(&p, end, binary, pr->type, &v, &line)) goto truncated;
                    if (pr->role >= 1 && pr->role <= 3) xyz[pr->role - 1] = v;
                    continue;
                }
                double cnt;
                if (ply_value(&p, end, binary, pr->count_type, &cnt, &line)) goto truncated;
                if (cnt < 0 || cnt > INT32_MAX || cnt != floor(cnt)) {
                    builder_free(&b);
                    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                        "%s%s: element %d item %lld: bad list length",
                                        name, ply_where(where, binary, line), i,
                                        item);
                }
                if (pr->role == 4 && cnt < 3) {
                    builder_free(&b);
                    return dk_error_set(err, DK_ERR_TOPOLOGY,
                                        "%s%s: face %lld has %d corners; at least 3 are "
                                        "needed",
                                        name, ply_where(where, binary, line), item, (int)cnt);
                }
                for (long long c = 0; c < (long long)cnt; c++) {
                    if (ply_value(&p, end, binary, pr->type, &v, &line)) goto truncated;
                    if (pr->role != 4) continue;
                    if (v < 0 || v >= (double)nv || v != floor(v)) {
                        builder_free(&b);
                        return dk_error_set(err, DK_ERR_INDEX,
                                            "%s%s: face %lld index %g is out of range "
                                            "[0, %lld]",
                                            name, ply_where(where, binary, line), item, v, nv - 1);
                    }
                    if (push_index(&b, (dk_index)v)) goto oom;
                }
                if (pr->role == 4 && push_size(&b, (dk_index)cnt)) goto oom;
            }
            if (e->kind == 1) {
                if (!isfinite(xyz[0]) || !isfinite(xyz[1]) || !isfinite(xyz[2])) {
                    builder_free(&b);
                    return dk_error_set(err, DK_ERR_NONFINITE,
                                        "%s%s: vertex %lld has a non-finite coordinate",
                                        name, ply_where(where, binary, line), item);
                }
                if (push_vertex(&b, xyz[0], xyz[1], xyz[2])) goto oom;
            }
        }
    }
    return builder_finish(&b, out, name, err);
truncated:
    builder_free(&b);
    return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s%s: PLY data ends early or is malformed",
                        name, ply_where(where, binary, line));
oom:
    builder_free(&b);
    return OOM(name);
}

/* ------------------------------------------------------------------ entry points -------- */

static int ends_with(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    if (n < m) return 0;
    for (size_t i = 0; i < m; i++)
        if (tolower((unsigned char)s[n - m + i]) != suffix[i]) return 0;
    return 1;
}

/* Parses `len` bytes at buf (NUL-terminated at buf[len]); the format from `name`'s
 * extension, else sniffed from the first bytes. On failure `*out` is zeroed. */
static dk_status parse_mesh(const char *buf, size_t len, const char *name, dk_mesh_file *out,
                            dk_error *err)
{
    dk_status st;
    if (ends_with(name, ".ply") || (len >= 3 && strncmp(buf, "ply", 3) == 0))
        st = read_ply(buf, len, name, out, err);
    else if (ends_with(name, ".off") || (len >= 3 && strncmp(buf, "OFF", 3) == 0))
        st = read_off(buf, name, out, err);
    else if (ends_with(name, ".obj"))
        st = read_obj(buf, name, out, err);
    else
        st = dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                          "%s: unknown mesh format (expected .obj, .off or .ply)", name);
    if (st) memset(out, 0, sizeof *out);
    return st;
}

dk_status dk_read_mesh_file(const char *path, dk_mesh_file *out, dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "read mesh: out is NULL");
    memset(out, 0, sizeof *out);
    if (!path) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "read mesh: path is NULL");
    const char *name = strrchr(path, '/');
    name = name ? name + 1 : path;
    /* Open without blocking (a FIFO would wait for a writer), then look before reading:
     * only a regular file (symlinks followed) of a bounded size is read; a device such as
     * /dev/zero, a FIFO or a directory would never end or is not a mesh. */
    int fd = open(path, O_RDONLY | O_NONBLOCK);
    if (fd < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: cannot open (%s)", path,
                            strerror(errno));
    struct stat sb;
    if (fstat(fd, &sb) != 0) {
        int e = errno;
        close(fd);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: cannot examine (%s)", path,
                            strerror(e));
    }
    if (!S_ISREG(sb.st_mode)) {
        const char *kind = S_ISDIR(sb.st_mode)    ? "a directory"
                           : S_ISFIFO(sb.st_mode) ? "a FIFO (named pipe)"
                           : S_ISCHR(sb.st_mode)  ? "a character device"
                           : S_ISBLK(sb.st_mode)  ? "a block device"
                           : S_ISSOCK(sb.st_mode) ? "a socket"
                                                  : "not a regular file";
        close(fd);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: is %s; only regular mesh files are read", path, kind);
    }
    if ((uint64_t)sb.st_size > (uint64_t)DK_MESH_FILE_MAX_BYTES) {
        close(fd);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: is %lld bytes, more than the %lld-byte limit of mesh files "
                            "(DK_MESH_FILE_MAX_BYTES)", path, (long long)sb.st_size,
                            (long long)DK_MESH_FILE_MAX_BYTES);
    }
    int flags = fcntl(fd, F_GETFL);
    if (flags >= 0)
        (void)fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);
    FILE *f = fdopen(fd, "rb");
    if (!f) {
        int e = errno;
        close(fd);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: cannot open (%s)", path,
                            strerror(e));
    }
    /* The size may change while reading (a file being written): read at most the limit
     * plus one byte, whatever fstat said, and refuse a file that grew past it. */
    char *buf = NULL;
    size_t len = 0, cap = 0;
    const size_t limit = (size_t)DK_MESH_FILE_MAX_BYTES;
    for (;;) {
        if (cap - len < 65536 && cap < limit + 2) {
            size_t want = (size_t)sb.st_size + 65536;
            size_t ncap = cap ? cap * 2 : (want < ((size_t)1 << 20) ? (size_t)1 << 20 : want);
            if (ncap > limit + 2)
                ncap = limit + 2; /* room for the limit, one byte more, and the NUL */
            char *nb = realloc(buf, ncap);
            if (!nb) {
                free(buf);
                fclose(f);
                return OOM(name);
            }
            buf = nb;
            cap = ncap;
        }
        size_t got = fread(buf + len, 1, cap - len - 1, f);
        len += got;
        if (got == 0) break;
        if (len > limit) {
            free(buf);
            fclose(f);
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s: grew past the %lld-byte limit of mesh files while being "
                                "read", path, (long long)DK_MESH_FILE_MAX_BYTES);
        }
    }
    int bad = ferror(f);
    fclose(f);
    if (bad) {
        free(buf);
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: read error", path);
    }
    buf[len] = '\0';
    dk_status st = parse_mesh(buf, len, name, out, err);
    free(buf);
    return st;
}

dk_status dk_read_mesh_memory(const char *data, size_t size, const char *name,
                              dk_mesh_file *out, dk_error *err)
{
    if (!out) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "read mesh: out is NULL");
    memset(out, 0, sizeof *out);
    if (!name) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "read mesh: name is NULL");
    if (!data && size)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "read mesh: data is NULL");
    if ((uint64_t)size > (uint64_t)DK_MESH_FILE_MAX_BYTES)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: is %llu bytes, more than the %lld-byte limit of mesh files "
                            "(DK_MESH_FILE_MAX_BYTES)", name, (unsigned long long)size,
                            (long long)DK_MESH_FILE_MAX_BYTES);
    /* the parsers want a NUL after the data */
    char *buf = malloc(size + 1);
    if (!buf) return OOM(name);
    if (size) memcpy(buf, data, size);
    buf[size] = '\0';
    dk_status st = parse_mesh(buf, size, name, out, err);
    free(buf);
    return st;
}

void dk_mesh_file_free(dk_mesh_file *file)
{
    if (!file) return;
    dk_free_mesh_arrays(file->positions, file->face_sizes, file->indices);
    memset(file, 0, sizeof *file);
}

dk_status dk_read_mesh_arrays(const char *path, double **positions, dk_index *n_vertices,
                              dk_index **face_sizes, dk_index *n_polygons, dk_index **indices,
                              int64_t *n_indices, dk_error *err)
{
    if (!positions || !n_vertices || !face_sizes || !n_polygons || !indices || !n_indices)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "read mesh: NULL output");
    dk_mesh_file m;
    dk_status st = dk_read_mesh_file(path, &m, err);
    *positions = m.positions;
    *n_vertices = m.n_vertices;
    *face_sizes = m.face_sizes;
    *n_polygons = m.n_polygons;
    *indices = m.indices;
    *n_indices = m.n_indices;
    return st;
}

void dk_free_mesh_arrays(double *positions, dk_index *face_sizes, dk_index *indices)
{
    free(positions);
    free(face_sizes);
    free(indices);
}

dk_status dk_write_obj(const char *path, const double *positions, dk_index n_vertices,
                       const dk_index *face_sizes, dk_index n_polygons,
                       const dk_index *indices, dk_error *err)
{
    if (!path || n_vertices < 0 || n_polygons < 0 || (n_vertices && !positions) ||
        (n_polygons && !indices))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "write obj: invalid argument");
    int64_t off = 0;
    for (dk_index p = 0; p < n_polygons; p++) {
        dk_index k = face_sizes ? face_sizes[p] : 3;
        if (k < 3)
            return dk_error_set(err, DK_ERR_TOPOLOGY,
                                "write obj: polygon %ld has %ld corners", (long)p, (long)k);
        for (dk_index c = 0; c < k; c++)
            if (indices[off + c] < 0 || indices[off + c] >= n_vertices)
                return dk_error_set(err, DK_ERR_INDEX,
                                    "write obj: polygon %ld corner %ld is %ld, out of range "
                                    "[0, %ld]",
                                    (long)p, (long)c, (long)indices[off + c],
                                    (long)n_vertices - 1);
        off += k;
    }
    FILE *f = fopen(path, "wb");
    if (!f)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: cannot open for writing (%s)",
                            path, strerror(errno));
    int bad = 0;
    for (dk_index v = 0; v < n_vertices && !bad; v++) {
        const double *q = positions + 3 * (int64_t)v;
        bad = fprintf(f, "v %.17g %.17g %.17g\n", q[0], q[1], q[2]) < 0;
    }
    off = 0;
    for (dk_index p = 0; p < n_polygons && !bad; p++) {
        dk_index k = face_sizes ? face_sizes[p] : 3;
        bad = fputc('f', f) == EOF;
        for (dk_index c = 0; c < k && !bad; c++)
            bad = fprintf(f, " %ld", (long)indices[off + c] + 1) < 0;
        if (!bad) bad = fputc('\n', f) == EOF;
        off += k;
    }
    if (fclose(f) != 0) bad = 1;
    if (bad) return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: write failed", path);
    return DK_OK;
}
