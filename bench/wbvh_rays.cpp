// Per-ray cost of the wide BVH against Embree in one process: the same scene, the same frames of
// changes and the same rays go to wbvh and to Embree (quality low and medium, accel/peers/
// embree_boxes.h), and every frame's ray batch is timed for each, alternating which goes first, in
// the thread's CPU time. Prints per query kind (all hits, closest, any) the median ns per ray over
// the measured frames with its range, the median of the per-frame ratios wbvh / each Embree (and
// / the faster Embree of that frame), and per ray the counters of one counted pass (counters.h):
// blocks visited (N_T), child boxes hit (N_TH), object box tests (N_RB), hits (N_TP), and the
// counting model's mispredicted steps and cache lines (N_MP, N_MISS). The hit lists of every
// structure are checked against the first's (sorted per ray; any hit: whether one was found).
//
// The scene follows `rcbench scene import`'s defaults: the file's boxes, then `frames` frames of 1%
// changes and `rays` centre rays each (add_dynamics, seeded). Pin it and repeat it; for
// instruction and cache-miss counts run it under callgrind with --instr-atstart=no: the timed
// batches alone are instrumented (docs/structures.md, wbvh):
//
//   build/bench/wbvh_rays BOXES.csv [key=value …]
//   build/bench/wbvh_rays RECORDING.rcbscene [key=value …]   (its own frames and rays)
//   build/bench/wbvh_rays generator=irregular objects=100000 [key=value …]
//     bench keys: frames=F (10), warmup=W (2; not in the medians), reps=R (1: batches per frame and
//                 structure), rays=N (1000), ray_mix=MIX (center; as scene import's --ray-mix),
//                 queries=PRESET (a game query preset instead, as --queries), seed=S (1),
//                 kinds=all,closest,any (the batches timed; `mix`: each ray its recorded kind),
//                 embree=low,medium (the Embree builds compared; none: wbvh alone), count=0|1 (1:
//                 the counted pass; 0 leaves only the timed batches, for valgrind), generator
//                 (`kind`, its old name, still works), objects (a generated scene)
//     wbvh.KEY=VALUE: a wbvh parameter, e.g. wbvh.push=loop
//     b.KEY=VALUE: a second wide BVH `wbvh_b` with these parameters, timed beside the first (A/B)
#include <algorithm>
#include <cstdio>
#include <ctime>
#include <memory>
#include <string>
#include <vector>

#include "bench/bench_util.h"
#include "accel/model/counters.h"
#include "accel/registry.h"
#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/import/csv.h"
#include "core/scene/recording_io.h"

#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#else
#define CALLGRIND_START_INSTRUMENTATION
#define CALLGRIND_STOP_INSTRUMENTATION
#endif

namespace {

using namespace rcb;

double cpu_ns() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return double(t.tv_sec) * 1e9 + double(t.tv_nsec);
}

struct Settings {
    std::string path;
    SceneSettings scene;
    std::uint32_t frames = 10, warmup = 2, reps = 1, rays = 1000;
    bool count = true;
    std::string ray_mix = "center", queries;
    std::vector<std::string> kinds{"all", "closest", "any"};
    std::vector<std::string> embree{"low", "medium"};
    nlohmann::json a = nlohmann::json::object(), b;  // b null: no second wide BVH
};

std::vector<std::string> split_list(const std::string& text) {
    std::vector<std::string> out;
    std::size_t start = 0;
    for (;;) {
        const std::size_t comma = text.find(',', start);
        out.push_back(text.substr(start, comma - start));
        if (comma == std::string::npos) return out;
        start = comma + 1;
    }
}

std::vector<std::string> parse_kinds(const std::string& text) {
    std::vector<std::string> kinds = split_list(text);
    for (const std::string& k : kinds)
        if (k != "all" && k != "closest" && k != "any" && k != "mix")
            throw InputError("kinds: '" + k + "' is none of all, closest, any, mix");
    return kinds;
}

Settings parse(int argc, char** argv) {
    Settings s;
    s.scene.generator.clear();
    s.scene.objects = 100000;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        const std::size_t eq = arg.find('=');
        if (eq == std::string::npos) {
            if (!s.path.empty()) throw InputError("usage: wbvh_rays [BOXES.csv | RECORDING] [key=value …]");
            s.path = arg;
            continue;
        }
        const std::string key = arg.substr(0, eq), value = arg.substr(eq + 1);
        const char* v = value.c_str();
        if (key == "frames")
            s.frames = std::uint32_t(bench::count_arg(v, "frames", 1, 100000));
        else if (key == "warmup")
            s.warmup = std::uint32_t(bench::count_arg(v, "warmup", 0, 100000));
        else if (key == "reps")
            s.reps = std::uint32_t(bench::count_arg(v, "reps", 1, 1000));
        else if (key == "rays")
            s.rays = std::uint32_t(bench::count_arg(v, "rays", 1, 10000000));
        else if (key == "count")
            s.count = bench::count_arg(v, "count", 0, 1) != 0;
        else if (key == "seed")
            s.scene.seed = bench::count_arg(v, "seed", 0, UINT64_MAX);
        else if (key == "objects")
            s.scene.objects = std::uint32_t(bench::count_arg(v, "objects", 1, kMaxSceneObjects));
        else if (key == "generator" || key == "kind")
            s.scene.generator = value;
        else if (key == "ray_mix")
            s.ray_mix = value;
        else if (key == "queries")
            s.queries = value;
        else if (key == "kinds")
            s.kinds = parse_kinds(value);
        else if (key == "embree")
            s.embree = value == "none" ? std::vector<std::string>{} : split_list(value);
        else if (key.starts_with("wbvh.") || key.starts_with("b.")) {
            const auto [name, json] = parse_key_value(arg.substr(key.find('.') + 1));
            nlohmann::json& params = key[0] == 'w' ? s.a : s.b;
            if (params.is_null()) params = nlohmann::json::object();
            params[name] = json;
        } else {
            throw InputError("unknown key '" + key + "' (see the top of bench/wbvh_rays.cpp)");
        }
    }
    if (s.path.empty() == s.scene.generator.empty())
        throw InputError("give a scene file or generator=GENERATOR, not both");
    if (s.warmup >= s.frames) throw InputError("warmup: must be below frames (" + std::to_string(s.frames) + ")");
    return s;
}

/// The scene as `scene import` makes it from a boxes file, a recording as it is, or a generated
/// object set given the same dynamics and rays.
Recording load(const Settings& s) {
    const bool csv = !s.path.empty() && s.path.size() >= 4 && s.path.substr(s.path.size() - 4) == ".csv";
    if (!s.path.empty() && !csv) return read_recording(s.path);
    std::vector<Object> objects = csv ? read_boxes_csv(s.path) : generate_objects(s.scene);
    if (objects.empty()) throw InputError(s.path + ": no boxes");
    RaySettings rays;
    rays.per_frame = s.rays;
    rays.mix = parse_ray_mix(s.ray_mix);
    if (!s.queries.empty()) rays = with_query_preset(rays, s.queries);
    return add_dynamics(std::move(objects), DynamicsSettings{}, rays, s.frames, s.scene.seed, {{"bench", "wbvh_rays"}});
}

/// One structure under test, with what it measured per query kind.
struct Candidate {
    std::string name;
    std::unique_ptr<Structure> s;
    HitLists hits;
    std::vector<std::vector<double>> ns;  // per kind: ns per ray of every measured batch
    std::vector<Counters> counted;        // per kind: the counted pass, summed over measured frames
};

/// The kinds of a batch asking `kind` of every ray (empty: all hits), or the frame's own (`mix`).
std::vector<QueryKind> batch_kinds(const std::string& kind, const Frame& frame) {
    if (kind == "mix") return frame.kinds;
    if (kind == "all") return {};
    return std::vector<QueryKind>(frame.rays.size(), kind == "closest" ? QueryKind::closest : QueryKind::any);
}

/// Each ray's hits in uid order, so that lists from different traversal orders compare.
HitLists sorted(HitLists h) {
    for (std::size_t r = 0; r < h.rays(); ++r)
        std::sort(h.uids.begin() + h.offsets[r], h.uids.begin() + h.offsets[r + 1]);
    return h;
}

/// Any hit may differ in which uid it finds, not in whether it finds one.
void check_same(const Candidate& first, const Candidate& other, const std::string& kind,
                std::span<const QueryKind> kinds, std::size_t frame) {
    bool same = first.hits.offsets == other.hits.offsets;
    const HitLists a = sorted(first.hits), b = sorted(other.hits);
    for (std::size_t r = 0; same && r < a.rays(); ++r) {
        const bool any = kind == "any" || (!kinds.empty() && kinds[r] == QueryKind::any);
        same = any || std::equal(a.of(r).begin(), a.of(r).end(), b.of(r).begin(), b.of(r).end());
    }
    if (!same)
        throw std::logic_error("frame " + std::to_string(frame + 1) + ", " + kind + " hits: " + other.name +
                               " differs from " + first.name);
}

/// Times every candidate's batch of `rays` asking `kind`, `reps` times, the first candidate
/// rotating with `sample`, and checks the answers agree.
void time_batch(std::vector<Candidate>& cs, std::size_t kind_index, const std::string& kind, const Frame& frame,
                std::size_t f, const Settings& s, bool measured, std::size_t& sample) {
    const std::vector<QueryKind> kinds = batch_kinds(kind, frame);
    const double rays = double(frame.rays.size());
    for (std::uint32_t r = 0; r < s.reps; ++r, ++sample) {
        for (std::size_t k = 0; k < cs.size(); ++k) {
            Candidate& c = cs[(k + sample) % cs.size()];
            CALLGRIND_START_INSTRUMENTATION;  // callgrind --instr-atstart=no: the batches alone
            const double t0 = cpu_ns();
            c.s->cast(frame.rays, kinds, c.hits);
            const double t = cpu_ns() - t0;
            CALLGRIND_STOP_INSTRUMENTATION;
            if (measured) c.ns[kind_index].push_back(t / rays);
        }
        for (std::size_t k = 1; k < cs.size(); ++k) check_same(cs[0], cs[k], kind, kinds, f);
    }
    if (!measured || !s.count) return;
    for (Candidate& c : cs) c.s->cast_counted(frame.rays, kinds, c.hits, c.counted[kind_index]);
}

void report(const std::vector<Candidate>& cs, std::size_t ki, const std::string& kind, double rays) {
    std::printf(
        "\n%s hits: ns per ray (median, min, max over batches) | per ray: blocks N_T, child boxes hit N_TH, "
        "object tests N_RB, hits N_TP, model N_MP, N_MISS\n",
        kind.c_str());
    for (const Candidate& c : cs) {
        const std::vector<double>& t = c.ns[ki];
        const Counters& n = c.counted[ki];
        std::printf("  %-14s %9.1f %9.1f %9.1f | %8.2f %8.2f %8.2f %7.3f %7.2f %8.2f\n", c.name.c_str(), median(t),
                    *std::min_element(t.begin(), t.end()), *std::max_element(t.begin(), t.end()), double(n.n_t) / rays,
                    double(n.n_th) / rays, double(n.n_rb) / rays, double(n.n_tp) / rays, double(n.n_mp) / rays,
                    double(n.n_miss) / rays);
    }
    // Ratios of batches timed side by side (same frame, same rep), medians over the batches.
    std::vector<std::size_t> peers, ours;
    for (std::size_t i = 0; i < cs.size(); ++i) (cs[i].name.starts_with("embree") ? peers : ours).push_back(i);
    for (std::size_t o : ours) {
        for (std::size_t p : peers) {
            std::vector<double> r;
            for (std::size_t j = 0; j < cs[o].ns[ki].size(); ++j) r.push_back(cs[o].ns[ki][j] / cs[p].ns[ki][j]);
            std::printf("  ratio %s / %s: %.3f\n", cs[o].name.c_str(), cs[p].name.c_str(), median(r));
        }
        if (peers.size() > 1) {
            std::vector<double> r;
            for (std::size_t j = 0; j < cs[o].ns[ki].size(); ++j) {
                double best = cs[peers[0]].ns[ki][j];
                for (std::size_t p : peers) best = std::min(best, cs[p].ns[ki][j]);
                r.push_back(cs[o].ns[ki][j] / best);
            }
            std::printf("  ratio %s / the faster Embree of each batch: %.3f\n", cs[o].name.c_str(), median(r));
        }
    }
    if (cs.size() > 1 && ours.size() == 2) {
        std::vector<double> r;
        for (std::size_t j = 0; j < cs[ours[0]].ns[ki].size(); ++j)
            r.push_back(cs[ours[1]].ns[ki][j] / cs[ours[0]].ns[ki][j]);
        std::printf("  ratio wbvh_b / wbvh: %.3f\n", median(r));
    }
}

std::vector<Candidate> make_candidates(const Settings& s) {
    std::vector<Candidate> cs;
    const StructureInfo& wbvh = find_structure("wbvh");
    const StructureInfo& embree = find_structure("embree");
    cs.push_back({"wbvh", wbvh.make(s.a, "wbvh."), {}, {}, {}});
    std::printf("wbvh %s\n", wbvh.complete(s.a, "wbvh.").dump().c_str());
    if (!s.b.is_null()) {
        cs.push_back({"wbvh_b", wbvh.make(s.b, "b."), {}, {}, {}});
        std::printf("wbvh_b %s\n", wbvh.complete(s.b, "b.").dump().c_str());
    }
    for (const std::string& q : s.embree) {
        const nlohmann::json p = {{"quality", q}};
        cs.push_back({"embree_" + q, embree.make(p, "embree"), {}, {}, {}});
        std::printf("embree_%s %s\n", q.c_str(), embree.complete(p, "embree").dump().c_str());
    }
    return cs;
}

int run(int argc, char** argv) {
    const Settings s = parse(argc, argv);
    const Recording rec = load(s);
    if (rec.frames.size() <= s.warmup) throw InputError("the scene has no frame after the warm-up");
    std::printf("%s: %zu objects, %zu frames (the first %u warm up), %zu rays in the last frame, %u reps\n",
                s.path.empty() ? s.scene.generator.c_str() : s.path.c_str(), rec.initial.size(), rec.frames.size(),
                s.warmup, rec.frames.back().rays.size(), s.reps);
    std::vector<Candidate> cs = make_candidates(s);
    for (Candidate& c : cs) {
        c.s->build(rec.initial);
        c.ns.resize(s.kinds.size());
        c.counted.resize(s.kinds.size());
    }
    std::size_t sample = 0;
    double rays = 0;
    for (std::size_t f = 0; f < rec.frames.size(); ++f) {
        const Frame& frame = rec.frames[f];
        for (Candidate& c : cs) {
            for (Uid uid : frame.removes) c.s->remove(uid);
            for (const Object& o : frame.inserts) c.s->insert(o);
            for (const Object& o : frame.moves) c.s->move(o);
            c.s->commit();
        }
        const bool measured = f >= s.warmup;
        if (measured) rays += double(frame.rays.size());
        for (std::size_t k = 0; k < s.kinds.size(); ++k) time_batch(cs, k, s.kinds[k], frame, f, s, measured, sample);
    }
    for (std::size_t k = 0; k < s.kinds.size(); ++k) report(cs, k, s.kinds[k], rays);
    for (const Candidate& c : cs)
        if (!c.name.starts_with("embree")) std::printf("%s stats %s\n", c.name.c_str(), c.s->stats().dump().c_str());
    std::printf("hit lists identical across structures\n");
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return rcb::bench::main_of("wbvh_rays", run, argc, argv); }
