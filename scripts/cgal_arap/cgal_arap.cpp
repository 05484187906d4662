// CGAL 5.5 reference for scripts/bench_arap.py: Surface_mesh_deformation, ORIGINAL_ARAP,
// on one scenario of ../shared/scenarios (JSON: mesh path relative to the JSON file, 0-based
// "fixed" indices, "handles" with "vertices" and "translate").
//
//   cgal_arap SCENARIO.json [--weights deformkit|cgal] [--max-iterations N]
//             [--preprocess-repeats R] [--stream]
//
// The OBJ is read by our own reader into a CGAL::Surface_mesh, vertex i of the file being
// Vertex_index(i) (nothing is merged, reordered or dropped; polygons are fan-triangulated
// like scripts/bench_common.load_obj). Region of interest: every vertex that lies in a
// triangle, plus the constrained ones; control vertices: the fixed and the handle vertices
// (a free vertex in no triangle would make CGAL's matrix singular: it is left out of the ROI
// and stays at rest, as DeformKit's bench does with roi=). Solver: CGAL's default
// Eigen::SparseLU with COLAMD ordering (CGAL keeps the constrained vertices as identity rows,
// so its matrix is not symmetric and a Cholesky solver does not apply as is).
//
// Weights (--weights):
//   deformkit (default): CGAL's weight-calculator hook (template parameter WC) with
//       DeformKit's "clamped_cotangent": per edge w = max(0, sum over its triangles of
//       cot(opposite angle) / 2), a triangle of area < 1e-14 longest_edge^2 contributing 0.
//       CGAL then minimises exactly the energy deformkit.ARAP(..., energy="spokes") reports.
//   cgal: CGAL's own default, CGAL::Weights::Cotangent_weight, which clamps every
//       triangle's cot/2 at 0 before summing: the same on edges whose two opposite angles are
//       both <= 90 degrees, smaller elsewhere (a different energy, hence minimiser).
//
// Output (stdout, text lines):
//   mesh <n_vertices> <n_triangles> <n_control>
//   construct <seconds>              constructor (halfedge weights) + ROI / control insertion
//   preprocess <best seconds> <ok>   preprocess() (region of solution, assembly, SparseLU),
//                                    best of R fresh objects
//   roi <n_roi>
//   iteration <k> <seconds>          wall time of the k-th deform(1, 0) call (CGAL's energy()
//                                    is private: the caller evaluates the streamed positions)
// With --stream each iteration line is followed by "positions <bytes>\n" and n_vertices x 3
// doubles (native byte order, file vertex order), then the program reads one line from
// stdin: "c" continues, anything else (or end of input) stops. This lets the caller evaluate
// each iterate without the evaluation running concurrently with CGAL's timed work.
// Exit status: 0 on success, 1 on bad input, 2 if preprocess() failed.

#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_deformation.h>

#include <boost/property_tree/json_parser.hpp>
#include <boost/property_tree/ptree.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

typedef CGAL::Simple_cartesian<double> Kernel;
typedef Kernel::Point_3 Point;
typedef Kernel::Vector_3 Vector;
typedef CGAL::Surface_mesh<Point> Mesh;
typedef boost::graph_traits<Mesh>::vertex_descriptor vertex_descriptor;
typedef boost::graph_traits<Mesh>::halfedge_descriptor halfedge_descriptor;

namespace {

struct Scenario {
    std::string name, mesh_path;
    std::vector<std::size_t> fixed;
    std::vector<std::vector<std::size_t>> handles;
    std::vector<Vector> translate;
};

struct Obj {
    std::vector<Point> vertices;
    std::vector<std::size_t> triangles; // 3 per triangle
};

// "v x y z" and "f i[/..] j[/..] k[/..] ..." lines; 1-based or negative (relative) indices.
Obj read_obj(const std::string &path)
{
    std::ifstream in(path);
    if (!in)
        throw std::runtime_error("cannot open " + path);
    Obj obj;
    std::string line;
    std::size_t line_no = 0;
    while (std::getline(in, line)) {
        line_no++;
        if (line.size() < 2 || line[1] != ' ' || (line[0] != 'v' && line[0] != 'f'))
            continue;
        std::istringstream ss(line.substr(2));
        if (line[0] == 'v') {
            double x, y, z;
            if (!(ss >> x >> y >> z))
                throw std::runtime_error(path + ":" + std::to_string(line_no) +
                                         ": bad vertex line");
            obj.vertices.emplace_back(x, y, z);
            continue;
        }
        std::vector<std::size_t> poly;
        std::string tok;
        while (ss >> tok) {
            long idx = std::strtol(tok.c_str(), nullptr, 10);
            long n = static_cast<long>(obj.vertices.size());
            long v = idx > 0 ? idx - 1 : n + idx;
            if (idx == 0 || v < 0 || v >= n)
                throw std::runtime_error(path + ":" + std::to_string(line_no) +
                                         ": face index " + tok + " out of range");
            poly.push_back(static_cast<std::size_t>(v));
        }
        for (std::size_t k = 1; k + 1 < poly.size(); k++) {
            obj.triangles.push_back(poly[0]);
            obj.triangles.push_back(poly[k]);
            obj.triangles.push_back(poly[k + 1]);
        }
    }
    return obj;
}

std::vector<std::size_t> index_list(const boost::property_tree::ptree &node)
{
    std::vector<std::size_t> out;
    for (const auto &child : node)
        out.push_back(child.second.get_value<std::size_t>());
    return out;
}

Scenario read_scenario(const std::string &path)
{
    boost::property_tree::ptree root;
    boost::property_tree::read_json(path, root);
    Scenario sc;
    sc.name = root.get<std::string>("name", "");
    std::string mesh = root.get<std::string>("mesh");
    std::string dir = path.find('/') == std::string::npos ? "." : path.substr(0, path.rfind('/'));
    sc.mesh_path = mesh.size() && mesh[0] == '/' ? mesh : dir + "/" + mesh;
    sc.fixed = index_list(root.get_child("fixed"));
    for (const auto &h : root.get_child("handles")) {
        sc.handles.push_back(index_list(h.second.get_child("vertices")));
        std::vector<double> t;
        for (const auto &c : h.second.get_child("translate"))
            t.push_back(c.second.get_value<double>());
        if (t.size() != 3)
            throw std::runtime_error("handle translate must have 3 entries");
        sc.translate.emplace_back(t[0], t[1], t[2]);
    }
    return sc;
}

// DeformKit's clamped cotangent spoke weight (see native/methods/arap.c, build_cells):
// w = max(0, sum over the edge's triangles of h), h = cot(opposite angle) / 2, or 0 when the
// triangle's area is below 1e-14 x its longest edge squared. CGAL calls this per halfedge;
// the value only depends on the edge, so both halfedges get the same weight, as with CGAL's
// own calculator.
struct DeformKit_clamped_cotangent {
    template <class VertexPointMap>
    static double half_cot(const Mesh &m, halfedge_descriptor h, VertexPointMap pmap)
    {
        if (is_border(h, m))
            return 0.0;
        const Point a = get(pmap, source(h, m)), b = get(pmap, target(h, m));
        const Point c = get(pmap, target(next(h, m), m)); // corner opposite the edge
        const Vector u = a - c, v = b - c;
        const double longest2 = (std::max)({(a - b).squared_length(), u.squared_length(),
                                            v.squared_length()});
        const double twice_area = std::sqrt(CGAL::cross_product(u, v).squared_length());
        if (!(0.5 * twice_area >= 1e-14 * longest2))
            return 0.0;
        return 0.5 * (u * v) / twice_area;
    }

    template <class VertexPointMap>
    double operator()(halfedge_descriptor h, const Mesh &m, VertexPointMap pmap) const
    {
        const double w = half_cot(m, h, pmap) + half_cot(m, opposite(h, m), pmap);
        return w > 0.0 ? w : 0.0;
    }
};

double seconds_since(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct Options {
    std::string scenario, weights = "deformkit";
    unsigned max_iterations = 100, preprocess_repeats = 3;
    bool stream = false;
};

template <class WC>
int run(const Options &opt, const Scenario &sc, Mesh &mesh)
{
    typedef CGAL::Surface_mesh_deformation<Mesh, CGAL::Default, CGAL::Default,
                                           CGAL::ORIGINAL_ARAP, WC>
        Deformation;
    const std::size_t n = num_vertices(mesh);
    std::vector<char> in_triangle(n, 0);
    for (auto f : faces(mesh))
        for (auto v : vertices_around_face(halfedge(f, mesh), mesh))
            in_triangle[v] = 1;
    std::vector<vertex_descriptor> control;
    for (std::size_t i : sc.fixed)
        control.push_back(vertex_descriptor(static_cast<Mesh::size_type>(i)));
    for (const auto &h : sc.handles)
        for (std::size_t i : h)
            control.push_back(vertex_descriptor(static_cast<Mesh::size_type>(i)));

    // Best of R preprocess() timings, each on a fresh object; the last object is used.
    std::unique_ptr<Deformation> deform;
    double construct_s = 0.0, preprocess_s = 1e300;
    bool ok = false;
    std::size_t n_roi = 0;
    for (unsigned r = 0; r < std::max(1u, opt.preprocess_repeats); r++) {
        deform.reset();
        auto t0 = std::chrono::steady_clock::now();
        deform.reset(new Deformation(mesh));
        std::vector<vertex_descriptor> roi;
        for (auto v : vertices(mesh))
            if (in_triangle[v])
                roi.push_back(v);
        deform->insert_roi_vertices(roi.begin(), roi.end());
        deform->insert_control_vertices(control.begin(), control.end());
        construct_s = seconds_since(t0);
        n_roi = deform->roi_vertices().size();
        t0 = std::chrono::steady_clock::now();
        ok = deform->preprocess();
        preprocess_s = std::min(preprocess_s, seconds_since(t0));
    }
    std::printf("construct %.6f\npreprocess %.6f %d\n", construct_s, preprocess_s, ok ? 1 : 0);
    std::printf("roi %zu\n", n_roi);
    std::fflush(stdout);
    if (!ok)
        return 2;
    for (std::size_t h = 0; h < sc.handles.size(); h++)
        for (std::size_t i : sc.handles[h]) {
            vertex_descriptor v(static_cast<Mesh::size_type>(i));
            deform->set_target_position(v, mesh.point(v) + sc.translate[h]);
        }
    std::vector<double> buf(3 * n);
    std::string reply;
    for (unsigned it = 1; it <= opt.max_iterations; it++) {
        auto t0 = std::chrono::steady_clock::now();
        deform->deform(1, 0.0);
        double dt = seconds_since(t0);
        std::printf("iteration %u %.6f\n", it, dt);
        if (opt.stream) {
            for (auto v : vertices(mesh)) {
                const Point &p = mesh.point(v);
                for (int d = 0; d < 3; d++)
                    buf[3 * static_cast<std::size_t>(v) + d] = p[d];
            }
            std::printf("positions %zu\n", buf.size() * sizeof(double));
            if (std::fwrite(buf.data(), sizeof(double), buf.size(), stdout) != buf.size())
                return 0; // reader went away
            std::fflush(stdout);
            if (!std::getline(std::cin, reply) || reply != "c")
                return 0;
        } else {
            std::fflush(stdout);
        }
    }
    return 0;
}

} // namespace

int main(int argc, char **argv)
{
    Options opt;
    for (int i = 1; i < argc; i++) {
        std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "cgal_arap: %s needs a value\n", a.c_str());
                std::exit(1);
            }
            return argv[++i];
        };
        if (a == "--weights")
            opt.weights = value();
        else if (a == "--max-iterations")
            opt.max_iterations = static_cast<unsigned>(std::stoul(value()));
        else if (a == "--preprocess-repeats")
            opt.preprocess_repeats = static_cast<unsigned>(std::stoul(value()));
        else if (a == "--stream")
            opt.stream = true;
        else if (!a.empty() && a[0] != '-' && opt.scenario.empty())
            opt.scenario = a;
        else {
            std::fprintf(stderr, "cgal_arap: unknown argument %s\n", a.c_str());
            return 1;
        }
    }
    if (opt.scenario.empty() || (opt.weights != "deformkit" && opt.weights != "cgal")) {
        std::fprintf(stderr, "usage: cgal_arap SCENARIO.json [--weights deformkit|cgal] "
                             "[--max-iterations N] [--preprocess-repeats R] [--stream]\n");
        return 1;
    }
    try {
        Scenario sc = read_scenario(opt.scenario);
        Obj obj = read_obj(sc.mesh_path);
        Mesh mesh;
        for (const Point &p : obj.vertices)
            mesh.add_vertex(p);
        std::size_t failed = 0;
        for (std::size_t t = 0; t < obj.triangles.size(); t += 3) {
            auto f = mesh.add_face(vertex_descriptor(static_cast<Mesh::size_type>(obj.triangles[t])),
                                   vertex_descriptor(static_cast<Mesh::size_type>(obj.triangles[t + 1])),
                                   vertex_descriptor(static_cast<Mesh::size_type>(obj.triangles[t + 2])));
            if (f == Mesh::null_face())
                failed++;
        }
        if (failed) {
            std::fprintf(stderr, "cgal_arap: %zu triangles could not be added (non-manifold)\n",
                         failed);
            return 1;
        }
        const std::size_t n = obj.vertices.size();
        for (const auto &list : {sc.fixed})
            for (std::size_t i : list)
                if (i >= n)
                    throw std::runtime_error("fixed index out of range");
        std::size_t n_control = sc.fixed.size();
        for (const auto &h : sc.handles) {
            n_control += h.size();
            for (std::size_t i : h)
                if (i >= n)
                    throw std::runtime_error("handle index out of range");
        }
        std::printf("mesh %zu %zu %zu\n", n, obj.triangles.size() / 3, n_control);
        std::fflush(stdout);
        if (opt.weights == "cgal")
            return run<CGAL::Default>(opt, sc, mesh);
        return run<DeformKit_clamped_cotangent>(opt, sc, mesh);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "cgal_arap: %s\n", e.what());
        return 1;
    }
}
