/* Fuzzes every method of dk_methods() through the contract (dk_method.h): bind, solve,
 * energy, stats, rebind and free.
 *
 * The input decodes, front to back, into
 *   1. the method (one byte, modulo the number of methods);
 *   2. a small mesh: mostly a W x H grid (2..6 each way) with bumps, jitter, coincident
 *      vertices, dropped or flipped triangles, loose vertices and a scale from 1e-150 to
 *      1e70; sometimes arbitrary polygons over up to 24 vertices;
 *   3. constraint groups: 0..3 handles of 0..4 vertices with optional weights, fixed
 *      vertices, an optional region of interest and optional stiffness (indices sometimes
 *      out of range, groups sometimes overlapping);
 *   4. the method's own options, filled through its table's option fields (dk_option_desc:
 *      no method is known here by name), each field valid most of the time and otherwise
 *      on a boundary (0, negative, NaN, Inf, 1e300, an enum one past its names);
 *   5. up to four solve requests (positions or transforms near the handles' rest, moved by
 *      up to a few bounding-box diagonals, sometimes raw doubles; any start, the given one
 *      from the rest positions; iteration cap, skip_energy and preview; a quarter of them
 *      with a pose to edit, input_positions), then a rebind
 *      with new groups and a solve after it.
 * A method bound to a control gets one of its kind (a lattice, a cage, bones: with their
 * weights or, a quarter of the time, with segments the bind computes the weights from).
 * Short inputs decode to small valid cases, so most inputs get through bind into solve.
 *
 * Checked besides the sanitizers (each is a promise of the contract):
 *   - a failure has a message; a bind that failed returns no object;
 *   - a solve that succeeded returns finite positions, and a finite energy unless skipped;
 *   - energy() of a solve's result is finite or an error;
 *   - a solve or rebind that failed changed nothing: stats, energy() of the rest positions
 *     and the first request's cold solve are bit for bit as before;
 *   - two cold solves of the first request are bit-identical, whatever came between. */
#include <stddef.h>
#include <stdint.h>

#include "dk_method.h"
#include "fuzz_input.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

enum { MAX_V = 48, MAX_P = 96, MAX_HANDLES = 3, MAX_HV = 12, MAX_FIXED = 8, MAX_REQUESTS = 4 };
enum { MAX_CONTROLS = 8, MAX_CAGE_TRIS = 12 };

/* ------------------------------------------------------------------ the mesh ----------- */

static dk_mesh *decode_mesh(dk_fuzz_input *in)
{
    double pos[3 * MAX_V];
    dk_index sizes[MAX_P], idx[4 * MAX_P];
    dk_index n = 0, np = 0;
    int64_t ni = 0;
    static const double scales[8] = {1, 1, 1, 1, 1e-6, 1e6, 1e70, 1e-150};
    const uint8_t kind = dk_fuzz_u8(in);
    if (kind % 8 != 7) {
        const int W = 2 + dk_fuzz_below(in, 5), H = 2 + dk_fuzz_below(in, 5);
        const uint8_t look = dk_fuzz_u8(in);
        const double scale = scales[look % 8];
        for (int j = 0; j < H; j++)
            for (int i = 0; i < W; i++, n++) {
                const uint8_t b = (look & 8) ? dk_fuzz_u8(in) : 0;
                pos[3 * n] = scale * (i + ((look & 16) ? 0.1 * ((b & 7) - 3.5) / 3.5 : 0));
                pos[3 * n + 1] = scale * (j + ((look & 16) ? 0.1 * (((b >> 3) & 7) - 3.5) / 3.5 : 0));
                pos[3 * n + 2] = scale * 0.2 * (((b >> 6) & 3) - 1.5);
            }
        if (look & 32) { /* a vertex onto its neighbour: zero-area triangles */
            const dk_index v = dk_fuzz_below(in, n - 1);
            memcpy(pos + 3 * v, pos + 3 * (v + 1), 3 * sizeof(double));
        }
        const int drop = (look & 64) != 0;
        for (int j = 0; j + 1 < H; j++)
            for (int i = 0; i + 1 < W; i++) {
                const uint8_t q = (drop || (look & 128)) ? dk_fuzz_u8(in) : 0;
                if (drop && q % 8 == 0) continue; /* a hole */
                const dk_index a = j * W + i, b = a + 1, c = a + W, d = c + 1;
                const int flip = (look & 128) && q % 16 == 1;
                if (q & 16) { /* split along b-c or a-d */
                    dk_index t[6] = {a, b, d, a, d, c};
                    for (int k = 0; k < 6; k++) idx[ni++] = t[k];
                } else {
                    dk_index t[6] = {a, b, c, b, d, c};
                    for (int k = 0; k < 6; k++) idx[ni++] = t[k];
                }
                if (flip) {
                    const dk_index tmp = idx[ni - 1];
                    idx[ni - 1] = idx[ni - 2];
                    idx[ni - 2] = tmp;
                }
                sizes[np++] = 3;
                sizes[np++] = 3;
            }
        const int loose = (look >> 1) & 3; /* 0..3 loose vertices (3: a loose triangle) */
        for (int k = 0; k < loose && n < MAX_V; k++, n++) {
            pos[3 * n] = scale * (W + 1 + k);
            pos[3 * n + 1] = scale * 0.5 * k;
            pos[3 * n + 2] = scale;
        }
        if (loose == 3) {
            sizes[np++] = 3;
            idx[ni++] = n - 3, idx[ni++] = n - 2, idx[ni++] = n - 1;
        }
    } else {
        n = 3 + dk_fuzz_below(in, 22);
        const int raw = dk_fuzz_u8(in) % 8 == 0;
        for (int i = 0; i < 3 * n; i++)
            pos[i] = raw ? dk_fuzz_raw_double(in) : (double)(dk_fuzz_u8(in) % 5) - 2.0;
        const int want = dk_fuzz_below(in, 32);
        for (int p = 0; p < want && ni + 4 <= 4 * MAX_P; p++) {
            const dk_index k = 3 + dk_fuzz_below(in, 2);
            sizes[np++] = k;
            for (dk_index c = 0; c < k; c++)
                idx[ni++] = dk_fuzz_below(in, n);
        }
    }
    dk_mesh *m = NULL;
    dk_error err = {0};
    if (dk_mesh_from_polygons(pos, n, sizes, np, idx, ni, &m, &err) != DK_OK)
        return NULL;
    return m;
}

/* ------------------------------------------------------------------ constraints -------- */

typedef struct groups {
    dk_index sizes[MAX_HANDLES], hv[MAX_HV], fixed[MAX_FIXED], roi[MAX_V];
    double weights[MAX_HV], stiffness[MAX_V];
    dk_constraint_desc desc;
    /* a control bound beside the groups (dk_controls.h), sometimes malformed */
    dk_control_desc control;
    double control_rest[16 * MAX_CONTROLS > 3 * MAX_CONTROLS * MAX_V ? 16 * MAX_CONTROLS
                                                                      : 3 * MAX_CONTROLS * MAX_V];
    dk_index control_tris[3 * MAX_CAGE_TRIS];
    double control_weights[MAX_CONTROLS * MAX_V];
    double control_segments[MAX_CONTROLS * 6];
} groups;

static dk_index decode_vertex(dk_fuzz_input *in, dk_index n)
{
    const uint8_t b = dk_fuzz_u8(in);
    if (b == 255) return n;  /* out of range */
    if (b == 254) return -1;
    return b % n;
}

static void decode_groups(dk_fuzz_input *in, dk_index n, groups *g)
{
    memset(g, 0, sizeof *g);
    const uint8_t shape = dk_fuzz_u8(in);
    /* one handle is the common case; none is refused */
    const int nh = shape % 8 == 0 ? 0 : 1 + (shape % 8) % MAX_HANDLES;
    dk_index total = 0;
    for (int h = 0; h < nh; h++) {
        const uint8_t c = dk_fuzz_u8(in);
        dk_index k = c % 16 == 0 ? 0 : 1 + c % 4;
        if (total + k > MAX_HV) k = MAX_HV - total;
        g->sizes[h] = k;
        for (dk_index i = 0; i < k; i++)
            g->hv[total + i] = decode_vertex(in, n);
        total += k;
    }
    g->desc.n_handles = nh;
    g->desc.handle_sizes = g->sizes;
    g->desc.handle_vertices = g->hv;
    if (shape & 8) {
        for (dk_index i = 0; i < total; i++)
            g->weights[i] = dk_fuzz_u8(in) % 8 == 0 ? dk_fuzz_real(in, 1.0)
                                                     : (1 + dk_fuzz_u8(in) % 8) / 8.0;
        g->desc.handle_weights = g->weights;
    }
    const dk_index nf = (shape >> 4) % 4 == 0 ? 0 : dk_fuzz_below(in, MAX_FIXED + 1);
    for (dk_index i = 0; i < nf; i++)
        g->fixed[i] = decode_vertex(in, n);
    g->desc.n_fixed = nf;
    g->desc.fixed_vertices = g->fixed;
    if ((shape >> 6) == 3) {
        const dk_index nr = 1 + dk_fuzz_below(in, n);
        for (dk_index i = 0; i < nr; i++)
            g->roi[i] = decode_vertex(in, n);
        g->desc.n_roi = nr;
        g->desc.roi_vertices = g->roi;
    }
    if ((shape >> 6) == 2) {
        for (dk_index v = 0; v < n; v++)
            g->stiffness[v] = dk_fuzz_u8(in) % 8 == 0 ? dk_fuzz_real(in, 1.0)
                                                       : 0.25 * (1 + dk_fuzz_u8(in) % 8);
        g->desc.stiffness = g->stiffness;
    }
}

/* One bind in eight carries a control of any kind -- every bind of a method that takes no
 * vertex groups, mostly of its own kind (`own`: its table's controls) -- every field
 * decoded within its buffer (n_controls, resolution and triangle corners may still be
 * wrong, values non-finite): dk_control_check must refuse the malformed ones with a
 * message, and a method whose table does not take the kind must refuse the bind. */
static void decode_control(dk_fuzz_input *in, const dk_mesh *m, unsigned own, groups *g)
{
    const dk_index n = m->n_vertices;
    const int controlled = !(own & DK_CONTROL_VERTEX_GROUPS);
    if ((!controlled && dk_fuzz_u8(in) % 8 != 0) || n > MAX_V)
        return;
    dk_control_desc *c = &g->control;
    c->kind = (dk_control_kind)(1u << dk_fuzz_below(in, 7)); /* 64: not a kind */
    if (controlled && dk_fuzz_u8(in) % 8 != 0)
        c->kind = (dk_control_kind)(own & (0u - own)); /* its first kind */
    c->n_controls = dk_fuzz_below(in, MAX_CONTROLS + 1);
    for (int k = 0; k < 3; k++)
        c->resolution[k] = c->kind == DK_CONTROL_LATTICE ? dk_fuzz_below(in, 3) + 1 : 0;
    if (c->kind == DK_CONTROL_LATTICE && dk_fuzz_u8(in) % 8 != 0) { /* mostly consistent */
        for (int k = 0; k < 3; k++)
            c->resolution[k] = c->resolution[k] < 2 ? 2 : c->resolution[k];
        c->n_controls = c->resolution[0] * c->resolution[1] * c->resolution[2];
    }
    const size_t per = c->kind == DK_CONTROL_POSES ? 3 * (size_t)n
                       : c->kind == DK_CONTROL_BONES || c->kind == DK_CONTROL_LATTICE ? 16
                                                                                      : 3;
    const size_t count = c->kind == DK_CONTROL_LATTICE ? 16 : per * (size_t)c->n_controls;
    for (size_t i = 0; i < count; i++)
        g->control_rest[i] = dk_fuzz_real(in, 1.0);
    if (c->kind == DK_CONTROL_BONES || c->kind == DK_CONTROL_LATTICE)
        for (size_t f = 0; f < count / 16; f++) { /* mostly affine frames */
            double *m = g->control_rest + 16 * f;
            if (dk_fuzz_u8(in) % 4 != 0) {
                m[12] = m[13] = m[14] = 0.0;
                m[15] = 1.0;
            }
        }
    if (c->kind == DK_CONTROL_LATTICE && dk_fuzz_u8(in) % 4 != 0) {
        /* mostly a box around the mesh, grown or shrunk a little (vertices in and out) */
        const double *lo = m->bbox_min, *hi = m->bbox_max;
        double *f = g->control_rest;
        memset(f, 0, 16 * sizeof(double));
        for (int d = 0; d < 3; d++) {
            const double w = hi[d] - lo[d] > 0 ? hi[d] - lo[d] : 1.0;
            const double grow = ((double)(dk_fuzz_u8(in) % 9) - 2) / 16.0;
            f[5 * d] = w * (1.0 + 2.0 * grow);
            f[4 * d + 3] = lo[d] - grow * w;
        }
        f[15] = 1.0;
    }
    if (c->kind == DK_CONTROL_CAGE && dk_fuzz_u8(in) % 4 != 0) {
        /* mostly a closed box cage around the mesh, its corners jittered */
        static const dk_index box[36] = {0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
                                         2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5};
        const double *lo = m->bbox_min, *hi = m->bbox_max;
        c->n_controls = 8;
        c->n_triangles = 12;
        memcpy(g->control_tris, box, sizeof box);
        c->triangles = g->control_tris;
        for (int q = 0; q < 8; q++)
            for (int d = 0; d < 3; d++) {
                const double w = hi[d] - lo[d] > 0 ? hi[d] - lo[d] : 1.0;
                g->control_rest[3 * q + d] = ((q >> d) & 1 ? hi[d] + 0.1 * w : lo[d] - 0.1 * w) +
                                             w * ((double)(dk_fuzz_u8(in) % 9) - 4) / 32.0;
            }
    }
    c->rest = dk_fuzz_u8(in) % 16 == 0 ? NULL : g->control_rest;
    if (c->kind == DK_CONTROL_CAGE) {
        c->n_triangles = dk_fuzz_below(in, MAX_CAGE_TRIS + 1);
        for (dk_index i = 0; i < 3 * c->n_triangles; i++)
            g->control_tris[i] = dk_fuzz_below(in, MAX_CONTROLS + 1) - 1;
        c->triangles = g->control_tris;
    }
    if (c->kind == DK_CONTROL_BONES && c->n_controls > 0) {
        for (dk_index v = 0; v < n; v++)
            for (dk_index b = 0; b < c->n_controls; b++)
                g->control_weights[v * c->n_controls + b] =
                    dk_fuzz_u8(in) % 8 == 0 ? dk_fuzz_real(in, 1.0)
                                            : (b == v % c->n_controls ? 1.0 : 0.0);
        c->weights = g->control_weights;
        if (dk_fuzz_u8(in) % 4 == 0) { /* bones whose weights the bind computes */
            for (dk_index i = 0; i < 6 * c->n_controls; i++) {
                const int d = (int)(i % 3);
                const double lo = m->bbox_min[d], hi = m->bbox_max[d];
                g->control_segments[i] = dk_fuzz_u8(in) % 8 == 0
                                             ? dk_fuzz_real(in, 1.0)
                                             : lo + (hi - lo) * (double)(dk_fuzz_u8(in) % 17) / 16.0;
            }
            c->segments = g->control_segments;
            c->weights = dk_fuzz_u8(in) % 16 == 0 ? g->control_weights : NULL; /* both: refused */
        }
    }
    dk_error err = {0};
    if (dk_control_check(c, n, &err) != DK_OK)
        dk_fuzz_check(err.message[0], "a refused %s control without a message",
                      dk_control_kind_name(c->kind));
    g->desc.control = c;
}

/* ------------------------------------------------------------------ options ------------ */

/* The options, filled through the method's table (dk_option_desc): no code here knows a
 * method by name, so a new method's options are fuzzed as soon as it is registered. */
typedef union options {
    max_align_t align;
    unsigned char bytes[1024];
} options;

enum { MAX_LISTS = 4, MAX_LIST = 4 };
typedef struct extras {
    dk_index lists[MAX_LISTS][MAX_LIST];
    double edge_values[3 * MAX_P + 2];
    double vertex_values[MAX_LISTS][MAX_V + 1];
} extras;

static void put_int(options *o, const dk_option_desc *f, int v)
{
    memcpy(o->bytes + f->offset, &v, sizeof v);
}

static void put_double(options *o, const dk_option_desc *f, double v)
{
    memcpy(o->bytes + f->offset, &v, sizeof v);
}

/* Fills the options of `ops` from its defaults, each field valid most of the time and
 * otherwise on a boundary (0, -1, NaN, Inf, 1e300, one past an enum or a range); returns
 * NULL (the defaults) one time in eight. Vertex lists come all or none (a method may want
 * them in pairs, as EmbeddedDeformation's cut); an edge map has the edge count, or one off
 * it (refused). */
static const void *decode_options(dk_fuzz_input *in, const dk_method_ops *ops,
                                  const dk_mesh *m, options *o, extras *x)
{
    if (dk_fuzz_u8(in) % 8 == 0) return NULL;
    dk_fuzz_check(ops->options_size <= sizeof o->bytes, "%s options over %zu bytes", ops->name,
                  sizeof o->bytes);
    const double diag = m->bbox_diagonal > 0 ? m->bbox_diagonal : 1;
    ops->default_options(o->bytes);
    const int lists = dk_fuzz_u8(in) % 8 == 0;
    int n_lists = 0;
    for (int i = 0; i < ops->n_option_fields; i++) {
        const dk_option_desc *f = &ops->option_fields[i];
        switch (f->type) {
        case DK_OPTION_INT: {
            const int lo = f->min < -1e6 ? -1000 : (int)f->min;
            put_int(o, f, dk_fuzz_int(in, lo, (int)(f->quick_max < lo + 200 ? f->quick_max
                                                                                : lo + 200),
                                      f->quick_max >= f->max));
            break;
        }
        case DK_OPTION_ENUM:
            put_int(o, f, (int)f->min + dk_fuzz_enum(in, (int)(f->max - f->min) + 1));
            break;
        case DK_OPTION_DOUBLE: {
            const double usual = f->flags & DK_OPTION_LENGTH ? f->usual * diag : f->usual;
            put_double(o, f, (f->flags & DK_OPTION_ZERO_AUTO) && dk_fuzz_u8(in) % 2
                                 ? 0.0
                                 : dk_fuzz_real(in, usual));
            break;
        }
        case DK_OPTION_SEED: {
            const uint64_t seed = dk_fuzz_u32(in);
            memcpy(o->bytes + f->offset, &seed, sizeof seed);
            break;
        }
        case DK_OPTION_VERTICES: {
            dk_index count = 0;
            const dk_index *list = NULL;
            if (lists && n_lists < MAX_LISTS) {
                count = 1 + dk_fuzz_u8(in) % MAX_LIST;
                for (dk_index k = 0; k < count; k++)
                    x->lists[n_lists][k] = decode_vertex(in, m->n_vertices);
                list = x->lists[n_lists++];
            }
            memcpy(o->bytes + f->offset, &list, sizeof list);
            memcpy(o->bytes + f->count_offset, &count, sizeof count);
            break;
        }
        case DK_OPTION_EDGE_VALUES: {
            const uint8_t mat = dk_fuzz_u8(in);
            if (mat % 4 == 0) {
                /* the edge count, or one off it (refused); the array has room for one more */
                dk_index count = m->n_edges + (mat / 4) % 3 - 1;
                if (count < 0) count = 0;
                for (dk_index e = 0; e < m->n_edges + 1 && e < 3 * MAX_P + 2; e++)
                    x->edge_values[e] = dk_fuzz_u8(in) % 8 == 0
                                            ? dk_fuzz_real(in, f->usual)
                                            : f->usual * 0.25 * (1 + dk_fuzz_u8(in) % 8);
                const double *values = x->edge_values;
                memcpy(o->bytes + f->offset, &values, sizeof values);
                memcpy(o->bytes + f->count_offset, &count, sizeof count);
            }
            break;
        }
        case DK_OPTION_VERTEX_VALUES: {
            const uint8_t pick = dk_fuzz_u8(in);
            if (pick % 4 == 0 && n_lists < MAX_LISTS) {
                /* the vertex count, or one off it (refused); room for one more */
                dk_index count = m->n_vertices + (pick / 4) % 3 - 1;
                if (count < 0) count = 0;
                double *values = x->vertex_values[n_lists++];
                for (dk_index v = 0; v < m->n_vertices + 1 && v < MAX_V + 1; v++)
                    values[v] = dk_fuzz_u8(in) % 8 == 0
                                    ? dk_fuzz_real(in, f->usual)
                                    : fmin(f->max, f->usual * 0.25 * (1 + dk_fuzz_u8(in) % 4));
                memcpy(o->bytes + f->offset, &values, sizeof values);
                memcpy(o->bytes + f->count_offset, &count, sizeof count);
            }
            break;
        }
        }
    }
    return o->bytes;
}

/* ------------------------------------------------------------------ requests ----------- */

typedef struct request {
    dk_solve_request rq;
    double targets[16 * MAX_HV > 3 * MAX_HV ? 16 * MAX_HV : 3 * MAX_HV];
    double input[3 * MAX_V]; /* input_positions, when the request has them */
} request;

/* A request for the handles of `g` (the groups bound): targets near their rest. */
static void decode_request(dk_fuzz_input *in, const dk_mesh *m, const groups *g, request *r)
{
    memset(r, 0, sizeof *r);
    const double diag = m->bbox_diagonal > 0 ? m->bbox_diagonal : 1;
    const uint8_t c = dk_fuzz_u8(in);
    r->rq.target_kind = c % 32 == 31 ? (dk_target_kind)2 : (dk_target_kind)(c % 2);
    r->rq.start = (dk_start)((c >> 1) % 3);
    if ((c >> 3) % 8 == 7) r->rq.start = (dk_start)4; /* refused */
    if ((c >> 3) % 8 == 6) { /* from the rest positions (refused by methods without it) */
        r->rq.start = DK_START_GIVEN;
        r->rq.start_positions = m->positions;
    }
    const uint8_t it = dk_fuzz_u8(in);
    r->rq.max_iterations = it % 4 ? 0 : it % 64 == 4 ? -1 : (it >> 2) % 20;
    r->rq.skip_energy = it % 128 == 127 ? 2 : (it >> 7);
    r->rq.preview = (c >> 6) == 3 ? 1 : 0; /* a quarter of the requests are previews */
    r->rq.targets = r->targets;
    const int raw = dk_fuzz_u8(in) % 32 == 0;
    const dk_control_desc *ctl = g->desc.control;
    if (ctl && ctl->rest && ctl->n_controls > 0 && dk_control_target_count(ctl) <= 192 &&
        dk_fuzz_u8(in) % 8 != 0) {
        /* the control's points near their rest (a lattice's from its box), as positions;
         * bones' frames near their rest frames, as transforms (bottom rows kept) */
        r->rq.target_kind = ctl->kind == DK_CONTROL_BONES ? DK_TARGETS_TRANSFORMS
                                                          : DK_TARGETS_POSITIONS;
        const size_t cnt = dk_control_target_count(ctl);
        for (size_t k = 0; k < cnt; k++) {
            double base = 0.0;
            if (ctl->kind == DK_CONTROL_LATTICE) {
                const dk_index q = (dk_index)(k / 3), res0 = ctl->resolution[0] > 1
                                                              ? ctl->resolution[0] : 2;
                const dk_index res1 = ctl->resolution[1] > 1 ? ctl->resolution[1] : 2;
                const dk_index res2 = ctl->resolution[2] > 1 ? ctl->resolution[2] : 2;
                const double u[3] = {(double)(q % res0) / (res0 - 1),
                                     (double)((q / res0) % res1) / (res1 - 1),
                                     (double)(q / (res0 * res1)) / (res2 - 1)};
                const double *f = ctl->rest + 4 * (k % 3);
                base = f[0] * u[0] + f[1] * u[1] + f[2] * u[2] + f[3];
            } else if (ctl->kind == DK_CONTROL_POINTS || ctl->kind == DK_CONTROL_CAGE ||
                       ctl->kind == DK_CONTROL_BONES) {
                base = ctl->rest[k];
            }
            const uint8_t b = dk_fuzz_u8(in);
            const int bottom = ctl->kind == DK_CONTROL_BONES && k % 16 >= 12;
            r->targets[k] = raw ? dk_fuzz_raw_double(in)
                            : bottom ? base
                                     : base + 0.5 * diag * ((double)(b % 33) - 16) / 16.0;
        }
    }
    dk_index off = 0;
    for (dk_index h = 0; h < g->desc.n_handles; h++) {
        const dk_index k = g->sizes[h];
        if (r->rq.target_kind == DK_TARGETS_TRANSFORMS) {
            double *T = r->targets + 16 * h;
            for (int i = 0; i < 16; i++)
                T[i] = i % 5 == 0 ? 1.0 : 0.0;
            for (int i = 0; i < 12; i++) {
                const uint8_t b = dk_fuzz_u8(in);
                T[i] += raw ? dk_fuzz_raw_double(in)
                            : (i % 4 == 3 ? diag : 0.5) * ((double)(b % 33) - 16) / 16.0;
            }
            if (dk_fuzz_u8(in) % 32 == 0) T[12] = 0.5; /* not an affine transform: refused */
        } else {
            for (dk_index i = 0; i < k; i++) {
                const dk_index v = g->hv[off + i];
                const double *p = m->positions + 3 * (v >= 0 && v < m->n_vertices ? v : 0);
                for (int d = 0; d < 3; d++) {
                    const uint8_t b = dk_fuzz_u8(in);
                    r->targets[3 * (off + i) + d] =
                        raw ? dk_fuzz_raw_double(in)
                            : p[d] + 2.0 * diag * ((double)(b % 33) - 16) / 16.0;
                }
            }
        }
        off += k;
    }
    /* a quarter of the requests edit a pose (refused by methods without edits_input): the
     * rest scaled, shifted and jittered per vertex, sometimes with a NaN (refused) */
    const uint8_t ib = dk_fuzz_u8(in);
    if (ib % 4 == 0 && m->n_vertices <= MAX_V) {
        const double scale = 1.0 + ((double)(dk_fuzz_u8(in) % 17) - 8) / 16.0;
        for (dk_index v = 0; v < m->n_vertices; v++)
            for (int d = 0; d < 3; d++)
                r->input[3 * v + d] = scale * m->positions[3 * v + d] +
                                      diag * ((double)(dk_fuzz_u8(in) % 9) - 4) / 64.0;
        if (ib % 64 == 4)
            r->input[3 * dk_fuzz_below(in, m->n_vertices)] = NAN;
        r->rq.input_positions = r->input;
    }
}

/* ------------------------------------------------------------------ the checks --------- */

static int same_bits(const double *a, const double *b, size_t n)
{
    return memcmp(a, b, n * sizeof(double)) == 0;
}

typedef struct state {
    dk_method_stats stats;
    double energy_rest; /* energy() of the rest positions, NaN when it failed */
    dk_status energy_status;
} state;

static void observe(const dk_method_ops *ops, void *obj, const dk_mesh *m, state *s)
{
    dk_error err = {0};
    memset(s, 0, sizeof *s);
    ops->stats(obj, &s->stats);
    s->energy_rest = NAN;
    s->energy_status = ops->energy(obj, m->positions, &s->energy_rest, &err);
    if (s->energy_status != DK_OK)
        dk_fuzz_check(err.message[0], "%s energy failed without a message", ops->name);
}

static void same_state(const dk_method_ops *ops, const state *a, const state *b,
                       const char *after)
{
    dk_fuzz_check(memcmp(&a->stats, &b->stats, sizeof a->stats) == 0,
                  "%s: a %s that failed changed the stats", ops->name, after);
    dk_fuzz_check(a->energy_status == b->energy_status &&
                      (a->energy_status != DK_OK ||
                       memcmp(&a->energy_rest, &b->energy_rest, sizeof(double)) == 0),
                  "%s: a %s that failed changed energy(rest): %.17g -> %.17g", ops->name,
                  after, a->energy_rest, b->energy_rest);
}

/* Solves; checks what a success promises and that a failure has a message. */
static dk_status solve(const dk_method_ops *ops, void *obj, const dk_mesh *m,
                       const dk_solve_request *rq, double *x)
{
    dk_error err = {0};
    dk_solve_info info;
    memset(&info, 0, sizeof info);
    const dk_status st = ops->solve(obj, rq, x, &info, &err);
    if (st != DK_OK) {
        dk_fuzz_check(err.message[0], "%s solve failed (%d) without a message", ops->name,
                      (int)st);
        return st;
    }
    for (int64_t i = 0; i < 3 * (int64_t)m->n_vertices; i++)
        dk_fuzz_check(isfinite(x[i]), "%s solve returned a non-finite coordinate %lld",
                      ops->name, (long long)i);
    dk_fuzz_check(rq->skip_energy || isfinite(info.energy),
                  "%s solve returned energy %g", ops->name, info.energy);
    double e = NAN;
    if (ops->energy(obj, x, &e, &err) == DK_OK)
        dk_fuzz_check(isfinite(e), "%s energy() returned %g without an error", ops->name, e);
    else
        dk_fuzz_check(err.message[0], "%s energy failed without a message", ops->name);
    return st;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    dk_fuzz_input in = dk_fuzz_begin(data, size);
    const dk_method_ops *const *all = dk_methods();
    int n_methods = 0;
    while (all[n_methods]) n_methods++;
    const dk_method_ops *ops = all[dk_fuzz_below(&in, n_methods)];

    dk_mesh *m = decode_mesh(&in);
    if (!m) return 0;
    const size_t N = 3 * (size_t)m->n_vertices;
    groups g, g2;
    options o;
    extras x;
    memset(&o, 0, sizeof o);
    memset(&x, 0, sizeof x);
    decode_groups(&in, m->n_vertices, &g);
    decode_control(&in, m, ops->controls, &g);
    const void *opts = decode_options(&in, ops, m, &o, &x);

    void *obj = NULL;
    dk_error err = {0};
    dk_status st = ops->bind(m, &g.desc, opts, &obj, &err);
    dk_fuzz_check(st != DK_OK || !g.desc.control || (ops->controls & (unsigned)g.control.kind),
                  "%s took %s, a control kind its table does not declare", ops->name,
                  dk_control_kind_name(g.control.kind));
    if (st != DK_OK) {
        dk_fuzz_check(obj == NULL, "%s bind failed (%d) but returned an object", ops->name,
                      (int)st);
        dk_fuzz_check(err.message[0], "%s bind failed (%d) without a message", ops->name,
                      (int)st);
        dk_mesh_free(m);
        return 0;
    }
    dk_fuzz_check(obj != NULL, "%s bind succeeded without an object", ops->name);
    double *x0 = malloc(N * sizeof(double)), *x1 = malloc(N * sizeof(double));
    if (!x0 || !x1) goto out;
    state before, after;
    observe(ops, obj, m, &before);
    dk_fuzz_check(before.stats.n_vertices == m->n_vertices, "%s stats: %d vertices of %d",
                  ops->name, (int)before.stats.n_vertices, (int)m->n_vertices);

    /* the first request, cold: the reference every later cold solve of it must equal */
    request first, r;
    decode_request(&in, m, &g, &first);
    first.rq.start = DK_START_COLD;
    const int have_first = solve(ops, obj, m, &first.rq, x0) == DK_OK;

    const int n_requests = dk_fuzz_below(&in, MAX_REQUESTS + 1);
    for (int k = 0; k < n_requests; k++) {
        decode_request(&in, m, &g, &r);
        observe(ops, obj, m, &before);
        if (solve(ops, obj, m, &r.rq, x1) != DK_OK) {
            observe(ops, obj, m, &after);
            same_state(ops, &before, &after, "solve");
        }
    }
    if (have_first) {
        dk_fuzz_check(solve(ops, obj, m, &first.rq, x1) == DK_OK,
                      "%s: a cold solve that succeeded before now fails", ops->name);
        dk_fuzz_check(same_bits(x0, x1, N), "%s: two cold solves of one request differ",
                      ops->name);
    }

    /* state (methods that carry it): saved, perhaps damaged (a byte flipped, the buffer cut
     * short), restored. A refused restore changes nothing; one that is taken continues
     * as the saved object: its next solve of a request equals the saved object's. */
    if (ops->state_size && dk_fuzz_u8(&in) % 2 == 0) {
        const size_t size = ops->state_size(obj);
        unsigned char *st_buf = malloc(size + 1);
        double *xs = malloc(N * sizeof(double));
        if (st_buf && xs && ops->save_state(obj, st_buf, size, &err) == DK_OK) {
            decode_request(&in, m, &g, &r);
            const int ok_a = solve(ops, obj, m, &r.rq, xs) == DK_OK;
            size_t use = size;
            const uint8_t damage = dk_fuzz_u8(&in);
            if (damage % 4 == 1)
                st_buf[dk_fuzz_below(&in, (int)(size < 4096 ? size : 4096))] ^=
                    (unsigned char)(1 + damage / 4);
            else if (damage % 4 == 2)
                use = (size_t)dk_fuzz_below(&in, (int)(size < 4096 ? size : 4096));
            observe(ops, obj, m, &before);
            if (ops->restore_state(obj, st_buf, use, &err) != DK_OK) {
                dk_fuzz_check(err.message[0], "%s restore_state failed without a message",
                              ops->name);
                observe(ops, obj, m, &after);
                same_state(ops, &before, &after, "restore_state");
            } else if (damage % 4 == 0 && ok_a && r.rq.start != DK_START_GIVEN) {
                dk_fuzz_check(solve(ops, obj, m, &r.rq, x1) == DK_OK && same_bits(xs, x1, N),
                              "%s: after restore_state a solve differs from the saved "
                              "object's",
                              ops->name);
            }
        }
        free(st_buf);
        free(xs);
    }

    /* a rebind with new groups; a failed one changes nothing */
    decode_groups(&in, m->n_vertices, &g2);
    decode_control(&in, m, ops->controls, &g2);
    observe(ops, obj, m, &before);
    if (ops->rebind(obj, &g2.desc, &err) != DK_OK) {
        dk_fuzz_check(err.message[0], "%s rebind failed without a message", ops->name);
        observe(ops, obj, m, &after);
        same_state(ops, &before, &after, "rebind");
        if (have_first) {
            dk_fuzz_check(solve(ops, obj, m, &first.rq, x1) == DK_OK,
                          "%s: after a failed rebind the first request fails", ops->name);
            dk_fuzz_check(same_bits(x0, x1, N),
                          "%s: after a failed rebind the first request's result differs",
                          ops->name);
        }
    } else {
        decode_request(&in, m, &g2, &r);
        solve(ops, obj, m, &r.rq, x1);
    }
out:
    free(x0);
    free(x1);
    ops->free(obj);
    dk_mesh_free(m);
    return 0;
}
