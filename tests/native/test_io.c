/* Tests for dk_io: every real mesh in DK_SHARED_DIR/meshes (vertex counts from SOURCES.md,
 * valid meshes after triangulation), crafted OBJ/OFF/PLY files covering the syntax variants
 * and the error messages (file and line), and an OBJ write/read round trip. */
#define _POSIX_C_SOURCE 200809L
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "dk_io.h"
#include "dk_mesh.h"
#include "dk_test.h"
#include "dk_test_meshes.h"

#ifndef DK_SHARED_DIR
#define DK_SHARED_DIR "../shared"
#endif

static dk_mesh *load_and_build(const char *path, dk_mesh_file *f)
{
    dk_error err = {0};
    dk_mesh *m = NULL;
    dk_status st = dk_read_mesh_file(path, f, &err);
    CHECK_MSG(st == DK_OK, "%s", err.message);
    if (st) return NULL;
    st = dk_mesh_from_polygons(f->positions, f->n_vertices, f->face_sizes, f->n_polygons,
                               f->indices, f->n_indices, &m, &err);
    CHECK_MSG(st == DK_OK, "%s: %s", path, err.message);
    return m;
}

static void test_real_meshes(void)
{
    static const struct {
        const char *name;
        dk_index n_vertices;
    } files[] = {{"armadillo.obj", 43243}, {"arm.obj", 8311},          {"stanford-bunny.obj", 35947},
                 {"ogre.obj", 62194},      {"beast.obj", 32311},       {"spot.obj", 2930},
                 {"elephant.obj", 6034},   {"camelhead.off", 11381},   {"bumpy.off", 1250},
                 {"decimated-knight.off", 502}, {"horse.ply", 48485}};
    char path[4096];
    snprintf(path, sizeof path, "%s/meshes/SOURCES.md", DK_SHARED_DIR);
    FILE *probe = fopen(path, "rb");
    if (!probe) {
        printf("note: %s/meshes not found; real-mesh tests skipped\n", DK_SHARED_DIR);
        CHECK(1);
        return;
    }
    fclose(probe);
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        if (!dk_test_shared_mesh_path(DK_SHARED_DIR, files[i].name, path, sizeof path)) continue;
        dk_mesh_file f;
        dk_mesh *m = load_and_build(path, &f);
        CHECK_MSG(f.n_vertices == files[i].n_vertices, "%s: %ld vertices, expected %ld",
                  files[i].name, (long)f.n_vertices, (long)files[i].n_vertices);
        if (m) {
            printf("%-22s V %6ld  polygons %6ld  triangles %6ld  E %6ld  boundary edges %ld  "
                   "components %ld\n",
                   files[i].name, (long)m->n_vertices, (long)m->n_polygons, (long)m->n_faces,
                   (long)m->n_edges, (long)m->report.n_boundary_edges,
                   (long)m->report.n_components);
            CHECK(m->n_faces >= f.n_polygons && m->n_polygons == f.n_polygons);
            CHECK(m->n_faces == f.n_indices - 2 * (int64_t)f.n_polygons);
            if (strcmp(files[i].name, "beast.obj") == 0) {
                int max_k = 0;
                for (dk_index p = 0; p < f.n_polygons; p++)
                    if (f.face_sizes[p] > max_k) max_k = f.face_sizes[p];
                CHECK_MSG(max_k > 4, "beast.obj should contain n-gons (max %d)", max_k);
            }
            if (strcmp(files[i].name, "camelhead.off") == 0)
                CHECK(m->report.n_boundary_edges > 0);
            if (strcmp(files[i].name, "armadillo.obj") == 0) {
                CHECK(m->report.n_boundary_edges == 0);
                CHECK(m->n_vertices - m->n_edges + m->n_faces == 2);
            }
        }
        dk_mesh_free(m);
        dk_mesh_file_free(&f);
    }
}

static dk_status read_text(const char *name, const char *text, dk_mesh_file *f, dk_error *err)
{
    if (dk_test_write_file(name, text)) {
        CHECK_MSG(0, "cannot write %s", name);
        memset(f, 0, sizeof *f);
        return DK_ERR_INTERNAL;
    }
    dk_status st = dk_read_mesh_file(name, f, err);
    remove(name);
    return st;
}

static void test_obj_syntax(void)
{
    dk_mesh_file f;
    dk_error err = {0};
    const char *obj = "# comment\nmtllib x.mtl\no thing\nv 0 0 0\nv 1 0 0 1.0\nvt 0 0\n"
                      "vn 0 0 1\nv 1 1 0\nv 0 1 0\ng grp\ns off\nusemtl m\n"
                      "f 1/1/1 2/1/1 3/1/1 4/1/1\nf -4//1 -2//1 -1//1\nf 1/2 2/2 3/2\r\n"
                      "l 1 2\n";
    CHECK(read_text("test_io_tmp_a.obj", obj, &f, &err) == DK_OK);
    CHECK(f.n_vertices == 4 && f.n_polygons == 3 && f.n_indices == 10);
    if (f.n_polygons == 3) {
        CHECK(f.face_sizes[0] == 4 && f.face_sizes[1] == 3);
        CHECK(f.indices[4] == 0 && f.indices[5] == 2 && f.indices[6] == 3);
        CHECK(f.positions[3] == 1.0 && f.positions[7] == 1.0);
    }
    dk_mesh_file_free(&f);
    CHECK(read_text("test_io_tmp_b.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 5\n", &f, &err) ==
          DK_ERR_INDEX);
    CHECK_MSG(strstr(err.message, "test_io_tmp_b.obj line 4") &&
                  strstr(err.message, "index 5"),
              "%s", err.message);
    CHECK(f.positions == NULL && f.n_vertices == 0);
    CHECK(read_text("test_io_tmp_c.obj", "v 0 0 0\nv 1 zero 0\n", &f, &err) ==
          DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(strstr(err.message, "test_io_tmp_c.obj line 2"), "%s", err.message);
    CHECK(read_text("test_io_tmp_d.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n", &f, &err) ==
          DK_ERR_TOPOLOGY);
    CHECK_MSG(strstr(err.message, "line 3") && strstr(err.message, "at least 3"), "%s",
              err.message);
    CHECK(read_text("test_io_tmp_e.obj", "v 0 0 0\nf 0 1 1\n", &f, &err) == DK_ERR_INDEX);
    CHECK(dk_read_mesh_file("/nonexistent/dir/x.obj", &f, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(strstr(err.message, "/nonexistent/dir/x.obj: cannot open"), "%s", err.message);
    CHECK(read_text("test_io_tmp_f.stl", "solid\n", &f, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(strstr(err.message, "unknown mesh format") != NULL);
}

static void test_off_syntax(void)
{
    dk_mesh_file f;
    dk_error err = {0};
    const char *off = "OFF\n# a comment\n4 2 0\n0 0 0\n1 0 0\n\n1 1 0 255 0 0\n0 1 0\n"
                      "3 0 1 2\n3 0 2 3 1 1 1\n";
    CHECK(read_text("test_io_tmp_a.off", off, &f, &err) == DK_OK);
    CHECK(f.n_vertices == 4 && f.n_polygons == 2 && f.n_indices == 6);
    if (f.n_indices == 6) CHECK(f.indices[5] == 3 && f.positions[7] == 1.0);
    dk_mesh_file_free(&f);
    CHECK(read_text("test_io_tmp_b.off", "OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", &f,
                    &err) == DK_OK);
    CHECK(f.n_vertices == 3 && f.n_polygons == 1);
    dk_mesh_file_free(&f);
    CHECK(read_text("test_io_tmp_c.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", &f,
                    &err) == DK_ERR_INDEX);
    CHECK_MSG(strstr(err.message, "test_io_tmp_c.off line 6") &&
                  strstr(err.message, "index 3 is out of range [0, 2]"),
              "%s", err.message);
    CHECK(read_text("test_io_tmp_d.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n", &f, &err) ==
          DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(strstr(err.message, "file ends early"), "%s", err.message);
}

static void test_ply_syntax(void)
{
    dk_mesh_file f;
    dk_error err = {0};
    const char *ply = "ply\nformat ascii 1.0\ncomment hi\nelement vertex 4\n"
                      "property double y_not\nproperty float x\nproperty float y\n"
                      "property float z\nproperty list uchar int extra\n"
                      "element face 2\nproperty uchar flags\n"
                      "property list uchar uint vertex_index\n"
                      "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
                      "end_header\n"
                      "9 0 0 0 2 7 7\n9 1 0 0 0\n9 1 1 0 1 5\n9 0 1 0 0\n"
                      "0 3 0 1 2\n1 4 0 1 2 3\n0 1\n";
    CHECK(read_text("test_io_tmp_a.ply", ply, &f, &err) == DK_OK);
    CHECK_MSG(f.n_vertices == 4 && f.n_polygons == 2 && f.n_indices == 7, "%s", err.message);
    if (f.n_indices == 7) CHECK(f.face_sizes[1] == 4 && f.indices[6] == 3);
    if (f.n_vertices == 4) CHECK(f.positions[6] == 1.0 && f.positions[7] == 1.0);
    dk_mesh_file_free(&f);

    /* binary little endian with mixed types: double x, float y, short z, list ushort int */
    unsigned char data[512];
    const char *hdr = "ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
                      "property double x\nproperty float y\nproperty short z\n"
                      "property uchar skip\nelement face 1\n"
                      "property list ushort int vertex_indices\nend_header\n";
    size_t n = strlen(hdr);
    memcpy(data, hdr, n);
    for (int v = 0; v < 3; v++) {
        double x = v * 1.5;
        float y = (float)(v == 2);
        int16_t z = (int16_t)(-v);
        memcpy(data + n, &x, 8);
        memcpy(data + n + 8, &y, 4);
        memcpy(data + n + 12, &z, 2);
        data[n + 14] = 0xAB;
        n += 15;
    }
    uint16_t cnt = 3;
    int32_t ids[3] = {2, 0, 1};
    memcpy(data + n, &cnt, 2);
    memcpy(data + n + 2, ids, 12);
    n += 14;
    FILE *out = fopen("test_io_tmp_b.ply", "wb");
    CHECK(out != NULL);
    if (out) {
        CHECK(fwrite(data, 1, n, out) == n);
        fclose(out);
        CHECK(dk_read_mesh_file("test_io_tmp_b.ply", &f, &err) == DK_OK);
        CHECK(f.n_vertices == 3 && f.n_polygons == 1);
        if (f.n_vertices == 3 && f.n_indices == 3) {
            CHECK(f.positions[3] == 1.5 && f.positions[7] == 1.0 && f.positions[8] == -2.0);
            CHECK(f.indices[0] == 2 && f.indices[2] == 1);
        }
        dk_mesh_file_free(&f);
        /* truncated */
        out = fopen("test_io_tmp_b.ply", "wb");
        if (out) {
            fwrite(data, 1, n - 3, out);
            fclose(out);
        }
        CHECK(dk_read_mesh_file("test_io_tmp_b.ply", &f, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK_MSG(strstr(err.message, "ends early"), "%s", err.message);
        remove("test_io_tmp_b.ply");
    }
    CHECK(read_text("test_io_tmp_d.ply",
                    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                    "property float y\nproperty float z\nelement face 1\n"
                    "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n"
                    "0 1 0\n3 0 1 7\n",
                    &f, &err) == DK_ERR_INDEX);
    CHECK_MSG(strstr(err.message, "test_io_tmp_d.ply line 13: face 0 index 7"), "%s",
              err.message);
    CHECK(read_text("test_io_tmp_c.ply", "ply\nformat binary_big_endian 1.0\nend_header\n", &f,
                    &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(strstr(err.message, "line 2") && strstr(err.message, "unsupported"), "%s",
              err.message);
}

static void test_write_roundtrip(void)
{
    dk_test_mesh g;
    CHECK(dk_test_icosphere(2, 1.5, &g) == 0);
    dk_error err = {0};
    CHECK(dk_write_obj("test_io_tmp_rt.obj", g.positions, g.n_vertices, NULL, g.n_faces,
                       g.faces, &err) == DK_OK);
    dk_mesh_file f;
    CHECK(dk_read_mesh_file("test_io_tmp_rt.obj", &f, &err) == DK_OK);
    CHECK(f.n_vertices == g.n_vertices && f.n_polygons == g.n_faces);
    if (f.n_vertices == g.n_vertices && f.n_indices == 3 * (int64_t)g.n_faces) {
        CHECK(memcmp(f.positions, g.positions, sizeof(double) * 3 * g.n_vertices) == 0);
        CHECK(memcmp(f.indices, g.faces, sizeof(dk_index) * 3 * g.n_faces) == 0);
    }
    dk_mesh_file_free(&f);
    /* the array form */
    double *pos;
    dk_index nv, np, *sizes, *idx;
    int64_t ni;
    CHECK(dk_read_mesh_arrays("test_io_tmp_rt.obj", &pos, &nv, &sizes, &np, &idx, &ni, &err) ==
          DK_OK);
    CHECK(nv == g.n_vertices && np == g.n_faces && ni == 3 * (int64_t)np && sizes[0] == 3);
    dk_free_mesh_arrays(pos, sizes, idx);
    remove("test_io_tmp_rt.obj");
    dk_index bad[3] = {0, 1, 999};
    CHECK(dk_write_obj("test_io_tmp_x.obj", g.positions, g.n_vertices, NULL, 1, bad, &err) ==
          DK_ERR_INDEX);
    CHECK_MSG(strstr(err.message, "corner 2 is 999"), "%s", err.message);
    dk_test_mesh_free(&g);
}

/* Issue 18, class 2: only regular files are read. A symlink x.obj -> /dev/zero, a FIFO and
 * a directory were read "to the end" (memory grew until the process was killed, or a FIFO
 * blocked forever); now each is refused before anything is read, naming what it is. */
static void test_refuses_non_regular_files(void)
{
    dk_mesh_file f;
    dk_error err = {0};
    remove("test_io_tmp_zero.obj");
    if (symlink("/dev/zero", "test_io_tmp_zero.obj") == 0) {
        CHECK(dk_read_mesh_file("test_io_tmp_zero.obj", &f, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK_MSG(strstr(err.message, "character device"), "%s", err.message);
        CHECK(f.positions == NULL);
        remove("test_io_tmp_zero.obj");
    }
    remove("test_io_tmp_fifo.obj");
    if (mkfifo("test_io_tmp_fifo.obj", 0600) == 0) {
        CHECK(dk_read_mesh_file("test_io_tmp_fifo.obj", &f, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK_MSG(strstr(err.message, "FIFO"), "%s", err.message);
        remove("test_io_tmp_fifo.obj");
    }
    rmdir("test_io_tmp_dir.obj");
    if (mkdir("test_io_tmp_dir.obj", 0700) == 0) {
        CHECK(dk_read_mesh_file("test_io_tmp_dir.obj", &f, &err) == DK_ERR_INVALID_ARGUMENT);
        CHECK_MSG(strstr(err.message, "directory"), "%s", err.message);
        rmdir("test_io_tmp_dir.obj");
    }
    /* a symlink to a regular file is followed */
    CHECK(dk_test_write_file("test_io_tmp_real.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n") == 0);
    remove("test_io_tmp_link.obj");
    if (symlink("test_io_tmp_real.obj", "test_io_tmp_link.obj") == 0) {
        CHECK(dk_read_mesh_file("test_io_tmp_link.obj", &f, &err) == DK_OK);
        CHECK(f.n_vertices == 3 && f.n_polygons == 1);
        dk_mesh_file_free(&f);
        remove("test_io_tmp_link.obj");
    }
    remove("test_io_tmp_real.obj");
    CHECK(DK_MESH_FILE_MAX_BYTES == (int64_t)2 * 1024 * 1024 * 1024);
}

/* Issue 18, item 11: the OBJ index error said "(0 vertices so far)" for a face before its
 * vertices, which OBJ writers produce; it now names the file's vertex count, and faces may
 * refer to vertices listed later. */
static void test_obj_index_messages(void)
{
    dk_mesh_file f;
    dk_error err = {0};
    CHECK(read_text("test_io_tmp_g.obj", "f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", &f, &err) ==
          DK_OK);
    CHECK(f.n_vertices == 3 && f.n_polygons == 1);
    dk_mesh_file_free(&f);
    CHECK(read_text("test_io_tmp_h.obj", "f 1 2 9\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", &f, &err) ==
          DK_ERR_INDEX);
    CHECK_MSG(strstr(err.message, "line 1: face index 9 is out of range [1, 3] (the file has "
                                  "3 vertices)"),
              "%s", err.message);
    CHECK(read_text("test_io_tmp_i.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n", &f,
                    &err) == DK_ERR_INDEX);
    CHECK_MSG(strstr(err.message, "relative face index -3") &&
                  strstr(err.message, "(2 vertices so far)"),
              "%s", err.message);
}

/* dk_read_mesh_memory parses as dk_read_mesh_file does (same format choice by the name's
 * extension, same messages), needs no NUL at the end, and refuses NULL arguments. */
static void test_read_from_memory(void)
{
    dk_mesh_file a, b;
    dk_error err = {0};
    const char *off = "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";
    CHECK(read_text("test_io_tmp_m.off", off, &a, &err) == DK_OK);
    /* no NUL after the data: ASan would see a read past the end */
    const size_t n = strlen(off);
    char *exact = malloc(n);
    if (!exact) return;
    memcpy(exact, off, n);
    CHECK_MSG(dk_read_mesh_memory(exact, n, "mem.off", &b, &err) == DK_OK, "%s", err.message);
    CHECK(a.n_vertices == b.n_vertices && a.n_polygons == b.n_polygons &&
          a.n_indices == b.n_indices);
    if (a.n_indices == b.n_indices && a.n_vertices == b.n_vertices) {
        CHECK(memcmp(a.indices, b.indices, sizeof(dk_index) * (size_t)a.n_indices) == 0);
        CHECK(memcmp(a.positions, b.positions, sizeof(double) * 3 * (size_t)a.n_vertices) == 0);
    }
    dk_mesh_file_free(&a);
    dk_mesh_file_free(&b);
    CHECK(dk_read_mesh_memory(exact, n - 4, "mem.off", &b, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK_MSG(strstr(err.message, "mem.off line 8"), "%s", err.message);
    CHECK(b.positions == NULL && b.n_vertices == 0);
    free(exact);
    CHECK(dk_read_mesh_memory("v 0 0 0\n", 8, "x.stl", &b, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(dk_read_mesh_memory(NULL, 4, "x.obj", &b, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(dk_read_mesh_memory("", 0, NULL, &b, &err) == DK_ERR_INVALID_ARGUMENT);
    CHECK(dk_read_mesh_memory(NULL, 0, "empty.obj", &b, &err) == DK_OK && b.n_vertices == 0);
    dk_mesh_file_free(&b);
}

/* What the fuzzers found in the readers (tests/fuzz/corpus/mesh_ply/crash-*). */
static void test_fuzz_findings(void)
{
    dk_mesh_file f;
    dk_error err = {0};
    /* 16 elements of 2^31 - 1 items without properties: no data, yet the reader walked
     * through every item (3.4e10 empty steps: minutes; fuzz_mesh_ply's timeout) */
    char ply[2048] = "ply\nformat binary_little_endian 1.0\nelement vertex 1\n"
                     "property float x\nproperty float y\nproperty float z\n";
    for (int i = 0; i < 15; i++)
        strcat(ply, "element junk 2147483647\n");
    strcat(ply, "end_header\n");
    size_t n = strlen(ply);
    const float xyz[3] = {1, 2, 3};
    memcpy(ply + n, xyz, sizeof xyz);
    n += sizeof xyz;
    CHECK_MSG(dk_read_mesh_memory(ply, n, "junk.ply", &f, &err) == DK_OK, "%s", err.message);
    CHECK(f.n_vertices == 1 && f.n_polygons == 0 && f.positions[2] == 3.0);
    dk_mesh_file_free(&f);
}

DK_TEST_MAIN(test_real_meshes, test_obj_syntax, test_off_syntax, test_ply_syntax,
             test_write_roundtrip, test_refuses_non_regular_files, test_obj_index_messages,
             test_read_from_memory, test_fuzz_findings)
