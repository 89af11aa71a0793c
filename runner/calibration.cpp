#include "runner/calibration.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <random>

#include "accel/builtin_structures.h"
#include "accel/model/counter_fields.h"
#include "core/base/error.h"
#include "core/base/stopwatch.h"
#include "core/truth/hit_lists.h"
#include "sim/simulator.h"
#include "runner/store.h"

namespace rcb {

namespace fs = std::filesystem;

std::uint64_t parse_cache_size(const std::string& text, const std::string& where) {
    std::size_t i = 0;
    std::uint64_t value = 0;
    while (i < text.size() && text[i] >= '0' && text[i] <= '9') {
        if (value > (std::uint64_t(1) << 40)) throw InputError(where + ": cache size '" + text + "' is too large");
        value = value * 10 + std::uint64_t(text[i++] - '0');
    }
    std::string unit = text.substr(i);
    while (!unit.empty() && (unit.back() == '\n' || unit.back() == ' ')) unit.pop_back();
    if (i == 0 || value == 0) throw InputError(where + ": not a cache size: '" + text + "'");
    if (unit.empty()) return value;
    if (unit == "K") return value << 10;
    if (unit == "M") return value << 20;
    if (unit == "G") return value << 30;
    throw InputError(where + ": not a cache size: '" + text + "'");
}

std::vector<CacheLevel> read_cache_sizes(const std::string& dir) {
    std::vector<CacheLevel> out;
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) return out;
    std::vector<fs::path> entries;
    for (const auto& e : fs::directory_iterator(dir, ec))
        if (e.path().filename().string().rfind("index", 0) == 0) entries.push_back(e.path());
    std::sort(entries.begin(), entries.end());
    auto read = [](const fs::path& p) {
        std::ifstream in(p);
        if (!in) throw InputError(p.string() + ": cannot be read");
        std::string line;
        std::getline(in, line);
        return line;
    };
    for (const fs::path& e : entries) {
        CacheLevel c;
        c.type = read(e / "type");
        if (c.type == "Instruction") continue;
        if (c.type != "Data" && c.type != "Unified")
            throw InputError((e / "type").string() + ": unknown cache type '" + c.type + "'");
        const std::string level = read(e / "level");
        if (level.empty() || level.size() > 2 || !std::all_of(level.begin(), level.end(), ::isdigit))
            throw InputError((e / "level").string() + ": not a cache level: '" + level + "'");
        c.level = std::stoi(level);
        c.bytes = parse_cache_size(read(e / "size"), (e / "size").string());
        out.push_back(c);
    }
    std::sort(out.begin(), out.end(), [](const CacheLevel& a, const CacheLevel& b) { return a.level < b.level; });
    return out;
}

std::uint64_t cold_sweep_bytes(const std::vector<CacheLevel>& caches) {
    std::uint64_t largest = 0;
    for (const CacheLevel& c : caches) largest = std::max(largest, c.bytes);
    return largest ? 2 * largest : std::uint64_t(64) << 20;
}

namespace {

/// A fixed generator: the micro-scenes are the same on every machine and every run.
constexpr std::uint64_t kSeed = 0x5eedca11b7a7e5ull;
struct Draw {
    std::mt19937_64 rng;
    explicit Draw(std::uint64_t seed) : rng(seed) {}
    float operator()(float lo, float hi) { return lo + (hi - lo) * float(double(rng() >> 11) * 0x1.0p-53); }
};

constexpr int kRays = 512;

/// The micro-scenes on the lattice of 32768 boxes, and how far their segments reach on each axis.
struct LargeScene {
    const char* name;
    float reach;
};
constexpr LargeScene kLargeScenes[] = {{"scatter-32", 60.f}, {"short-32", 12.f}};
/// The micro-scene that prices a reported hit apart from a box test.
constexpr const char* kHitsScene = "cluster";

/// A micro-scene: fixed objects, and rays of one kind drawn anew for every batch. Each timed repeat
/// casts new rays, as a run's frames do: a batch cast again and again would let the branch
/// predictor learn its outcomes and keep its lines cached, and price steps too low.
struct MicroScene {
    std::string name;
    std::vector<Object> objects;
    std::function<Segment(Draw&, int)> ray;  ///< the r-th ray of a batch
    int rays = kRays;
};

/// The first `rays` rays of batch `b` of the `index`-th micro-scene: its own generator, so any batch
/// is the same bytes on every run whatever was drawn before it (and a cut batch, kCutRays, is the
/// start of the full one).
std::vector<Segment> batch_of(const MicroScene& scene, std::size_t index, int b, int rays) {
    Draw draw(kSeed + 0x9e3779b97f4a7c15ull * (std::uint64_t(index) * 256 + std::uint64_t(b) + 1));
    std::vector<Segment> out;
    for (int r = 0; r < rays; ++r) out.push_back(scene.ray(draw, r));
    return out;
}

Aabb cube(Vec3 c, float half) { return {{c.x - half, c.y - half, c.z - half}, {c.x + half, c.y + half, c.z + half}}; }

/// Boxes of edge 2 at the centres of an n×n×n lattice of spacing 10 (the world is [0, 10n]^3).
std::vector<Object> lattice(int n) {
    std::vector<Object> out;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            for (int k = 0; k < n; ++k)
                out.push_back({Uid(out.size() + 1), cube({10.f * i + 5, 10.f * j + 5, 10.f * k + 5}, 1)});
    return out;
}

/// A hollow shell of boxes on the faces of [0, 100]^3.
std::vector<Object> shell() {
    std::vector<Object> out;
    for (int face = 0; face < 6; ++face)
        for (int a = 0; a < 13; ++a)
            for (int b = 0; b < 13; ++b) {
                const float u = 2 + 8.f * float(a), v = 2 + 8.f * float(b), f = face % 2 ? 99.f : 1.f;
                const Vec3 c = face / 2 == 0 ? Vec3{f, u, v} : face / 2 == 1 ? Vec3{u, f, v} : Vec3{u, v, f};
                out.push_back({Uid(out.size() + 1), cube(c, 1)});
            }
    return out;
}

/// Boxes of edge 0.5 at random in [40, 60]^3, and eight boxes at the corners of [0, 100]^3 that
/// set the world's bounds: at one object per cell a grid's cells are about 17 wide, so the cluster
/// falls in a few cells of some thirty boxes each.
std::vector<Object> cluster() {
    std::vector<Object> out;
    for (int c = 0; c < 8; ++c)
        out.push_back({Uid(out.size() + 1), cube({c & 1 ? 99.f : 1.f, c & 2 ? 99.f : 1.f, c & 4 ? 99.f : 1.f}, 1)});
    Draw draw(kSeed ^ 0xc1u);
    while (out.size() < 256)
        out.push_back({Uid(out.size() + 1), cube({draw(40, 60), draw(40, 60), draw(40, 60)}, 0.25f)});
    return out;
}

std::vector<MicroScene> micro_scenes() {
    std::vector<MicroScene> out;
    for (int n : {6, 10}) {
        const float w = 10.f * float(n);
        // Rays beside the world: start-up only.
        out.push_back({"outside-" + std::to_string(n), lattice(n), [w](Draw& draw, int) {
                           const Vec3 p0{w + 20 + draw(0, w), draw(0, w), draw(0, w)};
                           return Segment{p0, {p0.x + draw(5, w), p0.y + draw(-5, 5), p0.z + draw(-5, 5)}};
                       }});
        // Along the gaps between lattice rows: the whole width, no box met.
        out.push_back({"gaps-" + std::to_string(n), lattice(n), [n, w](Draw& draw, int r) {
                           const float y = 10.f * float(1 + r % (n - 1)) + draw(-1, 1),
                                       z = 10.f * float(1 + (r / 7) % (n - 1)) + draw(-1, 1);
                           return Segment{{-5, y, z}, {w + 5, y, z}};
                       }});
        // Along the rows: every ray meets the n boxes of its row.
        out.push_back({"rows-" + std::to_string(n), lattice(n), [n, w](Draw& draw, int r) {
                           const float y = 10.f * float(r % n) + 5 + draw(-0.5f, 0.5f),
                                       z = 10.f * float((r / 7) % n) + 5 + draw(-0.5f, 0.5f);
                           return Segment{{-5, y, z}, {w + 5, y, z}};
                       }});
    }
    // Random segments across the larger lattice: steps and tests in paths no ray before prepared
    // (many unpredicted steps, beside the rows' predictable ones).
    out.push_back(
        {"scatter-10", lattice(10), [](Draw& draw, int) {
             return Segment{{draw(0, 100), draw(0, 100), draw(0, 100)}, {draw(0, 100), draw(0, 100), draw(0, 100)}};
         }});
    // Rays inside the hollow shell: steps through empty space.
    out.push_back(
        {"shell", shell(), [](Draw& draw, int) {
             return Segment{{draw(15, 85), draw(15, 85), draw(15, 85)}, {draw(15, 85), draw(15, 85), draw(15, 85)}};
         }});
    // The same shell crossed kRays times by one long ray: steps like the random rays' above, but
    // each one predicted from the ray before (N_MP near 0), which pins C_MP against them.
    out.push_back({"shell-coherent", shell(), [](Draw&, int) { return Segment{{16, 20, 30}, {84, 80, 70}}; }});
    // A stack of identical boxes every ray crosses: box tests.
    std::vector<Object> stack;
    for (int i = 0; i < 256; ++i) stack.push_back({Uid(i + 1), cube({50, 50, 50}, 5)});
    out.push_back(
        {"stack", std::move(stack),
         [](Draw& draw, int) {
             return Segment{{draw(30, 40), draw(46, 54), draw(46, 54)}, {draw(60, 70), draw(46, 54), draw(46, 54)}};
         },
         kRays / 4});
    // Rays across the cluster that seldom hit one of its boxes: the many tests per cell of a
    // scene's dense region, nearly all missed, where the stack's tests all hit (C_HIT apart from
    // C_RB). A tree's tight bounds leave it a few tests per ray.
    out.push_back({kHitsScene, cluster(), [](Draw& draw, int) {
                       return Segment{{draw(38, 62), draw(38, 62), 30}, {draw(38, 62), draw(38, 62), 70}};
                   }});
    // Segments of up to 104 across a lattice of 32768 boxes: its nodes and cells outgrow a core's
    // private cache (and the simulated one of N_MISS), so new rays fetch lines where the small
    // scenes find theirs cached: C_MISS against the same steps and tests in cache.
    // Short ones (up to 21) fetch the few lines of a path's lower levels, in another proportion to
    // their steps.
    for (const LargeScene& large : kLargeScenes)
        out.push_back({large.name, lattice(32), [reach = large.reach](Draw& draw, int) {
                           const Vec3 p0{draw(0, 320), draw(0, 320), draw(0, 320)};
                           return Segment{
                               p0,
                               {p0.x + draw(-reach, reach), p0.y + draw(-reach, reach), p0.z + draw(-reach, reach)}};
                       }});
    return out;
}

/// What batch `rays` counts when cast right after `before`, as the timed cast met it: the counts of
/// both cast as one batch less those of `before` alone (the simulated cache and the predictor
/// start cold in each counted batch, and `before` leaves them as the timed cast before it did).
Counters counted_after(Structure& s, const std::vector<Segment>& before, const std::vector<Segment>& rays,
                       HitLists& hits) {
    Counters alone, both;
    s.cast_counted(before, hits, alone);
    std::vector<Segment> joined = before;
    joined.insert(joined.end(), rays.begin(), rays.end());
    s.cast_counted(joined, hits, both);
    Counters out;
    for (const CounterField& f : kCounterFields) {
        const std::uint64_t a = both.*f.member, b = alone.*f.member;
        out.*f.member = a > b ? a - b : 0;
    }
    return out;
}

}  // namespace

std::vector<CalibrationPoint> calibrate_if_buildable(const std::string& name, const nlohmann::json& params) {
    try {
        return calibrate_structure(find_structure(name), params);
    } catch (const std::exception&) {
        return {};
    }
}

bool prices_hits(const std::string& scene) { return scene == kHitsScene; }

bool outgrows_cache(const std::string& scene) {
    return std::any_of(std::begin(kLargeScenes), std::end(kLargeScenes),
                       [&](const LargeScene& large) { return scene == large.name; });
}

namespace {

/// A structure's calibration budget: its own time so far (the lesser of the wall and the thread's
/// CPU span, so that another process on the core does not spend it) against the seconds allowed.
class Budget {
public:
    explicit Budget(double seconds) : ns_(seconds * 1e9) {}
    /// Without a budget no clock is read (a system call), so a full calibration is as it was.
    bool spent() const { return std::isfinite(ns_) && double(clock_.ns(TimingClock::thread)) >= ns_; }

private:
    Stopwatch clock_;
    double ns_;
};

CalibrationPoint calibrate_on(const StructureInfo& info, const nlohmann::json& params, const MicroScene& scene,
                              std::size_t index, int repeats, const Budget& budget) {
    // A scene begun with the budget spent: one batch of the first kCutRays rays.
    const bool cut_before = budget.spent();
    const int rays = cut_before ? std::min(scene.rays, kCutRays) : scene.rays;
    if (cut_before) repeats = 1;
    std::unique_ptr<Structure> s = info.make(params, "calibration of " + info.name);
    s->build(scene.objects);
    s->commit();
    std::vector<std::vector<Segment>> batches;
    for (int b = 0; b <= repeats; ++b) batches.push_back(batch_of(scene, index, b, rays));
    HitLists hits;
    s->cast(batches[0], hits);  // warm the caches and branch predictors with rays of the kind
    std::vector<double> ns;
    for (int b = 1; b <= repeats; ++b) {
        const auto t0 = std::chrono::steady_clock::now();
        s->cast(batches[std::size_t(b)], hits);
        const auto t1 = std::chrono::steady_clock::now();
        ns.push_back(double(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count()) / double(rays));
    }
    // Counted after every timed cast, so that counting does not change what they found cached. The
    // budget is checked here, between untimed casts: the batches counted are those the point keeps.
    Counters counters;
    int counted = 0;
    while (counted < repeats && (counted == 0 || !budget.spent())) {
        ++counted;
        counters += counted_after(*s, batches[std::size_t(counted) - 1], batches[std::size_t(counted)], hits);
    }
    ns.resize(std::size_t(counted));
    const Spread spread = spread_of(ns);
    const double measured = double(rays) * double(counted);
    CalibrationPoint p;
    p.scene = scene.name;
    p.rays = std::uint32_t(rays);
    p.n_rb = double(counters.n_rb) / measured;
    p.n_t = double(counters.n_t) / measured;
    p.n_mp = double(counters.n_mp) / measured;
    p.n_miss = double(counters.n_miss) / measured;
    p.n_tp = double(counters.n_tp) / measured;
    p.n_dup = double(counters.n_dup) / measured;
    p.ns_per_ray = spread.median;
    p.mad = spread.mad;
    p.repeats = counted;
    p.cut = cut_before || counted < repeats;
    return p;
}

}  // namespace

double calibration_budget(const StructureInfo& info) {
    return rcbench_structure(info.name) ? std::numeric_limits<double>::infinity() : kCalibrationBudgetSeconds;
}

std::vector<CalibrationPoint> calibrate_structure(const StructureInfo& info, const nlohmann::json& params, int repeats,
                                                  double budget_seconds) {
    repeats = std::clamp(repeats, 1, 255);  // batch_of() keeps 256 seeds per scene
    std::vector<CalibrationPoint> out;
    const std::vector<MicroScene> scenes = micro_scenes();
    const Budget budget(budget_seconds < 0 ? calibration_budget(info) : budget_seconds);
    for (std::size_t i = 0; i < scenes.size(); ++i) {
        try {
            out.push_back(calibrate_on(info, params, scenes[i], i, repeats, budget));
        } catch (const std::exception&) {
            if (!outgrows_cache(scenes[i].name)) throw;
        }
    }
    return out;
}

namespace {

/// One structure's points of a calibration pass, measured before the transaction that stores them.
struct MeasuredPass {
    std::string name;
    nlohmann::json params;
    std::vector<CalibrationPoint> points;
};

std::vector<MeasuredPass> measure_pass(const CalibratedStructures& structures) {
    std::vector<MeasuredPass> out;
    for (const auto& [name, params] : structures) out.push_back({name, params, calibrate_if_buildable(name, params)});
    return out;
}

void store_pass(Database& db, std::int64_t run, std::int64_t pass, const std::vector<MeasuredPass>& measured) {
    Statement insert = db.prepare(
        "INSERT INTO calibration(run_id, structure, params, scene, rays, n_rb, n_t, ns_per_ray, mad, n_mp, n_miss, "
        "n_tp, pass, n_dup, repeats, cut) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
    for (const MeasuredPass& m : measured)
        for (const CalibrationPoint& p : m.points) {
            insert.reset();
            insert
                .bind_all(run, m.name, m.params.dump(), p.scene, std::int64_t(p.rays), p.n_rb, p.n_t, p.ns_per_ray,
                          p.mad, p.n_mp, p.n_miss, p.n_tp, pass, p.n_dup, std::int64_t(p.repeats), std::int64_t(p.cut))
                .run();
        }
}

}  // namespace

bool record_machine(Database& db, std::int64_t run, const CalibratedStructures& structures,
                    const std::string& cache_dir) {
    auto recorded = [&] {
        Statement s =
            db.prepare("SELECT 1 FROM run_cache WHERE run_id = ? UNION ALL SELECT 1 FROM calibration WHERE run_id = ?");
        s.bind_all(run, run);
        return s.step();
    };
    if (recorded()) return false;  // a resumed run keeps the machine state it began with
    const std::vector<CacheLevel> caches = read_cache_sizes(cache_dir);
    const std::vector<MeasuredPass> measured = measure_pass(structures);
    Transaction t(db);
    if (recorded()) return false;  // another runner of the same run stored it meanwhile
    for (const CacheLevel& c : caches)
        db.prepare("INSERT INTO run_cache(run_id, level, type, size_bytes) VALUES (?,?,?,?)")
            .bind_all(run, std::int64_t(c.level), c.type, std::int64_t(c.bytes))
            .run();
    store_pass(db, run, 0, measured);
    t.commit();
    return true;
}

void add_calibration_pass(Database& db, std::int64_t run, const CalibratedStructures& structures) {
    const std::vector<MeasuredPass> measured = measure_pass(structures);
    Transaction t(db);
    Statement next = db.prepare("SELECT coalesce(max(pass) + 1, 0) FROM calibration WHERE run_id = ?");
    next.bind(1, run);
    next.step();
    store_pass(db, run, next.int64(0), measured);
    t.commit();
}

std::vector<CacheLevel> load_cache_sizes(Database& db, std::int64_t run) {
    std::vector<CacheLevel> out;
    Statement s = db.prepare("SELECT level, type, size_bytes FROM run_cache WHERE run_id = ? ORDER BY level, type");
    s.bind(1, run);
    while (s.step()) out.push_back({int(s.int64(0)), s.text(1), std::uint64_t(s.int64(2))});
    return out;
}

std::vector<CalibrationPoint> load_calibration(Database& db, std::int64_t run, const std::string& structure) {
    std::vector<CalibrationPoint> out;
    Statement s = db.prepare(
        "SELECT scene, rays, n_rb, n_t, ns_per_ray, mad, n_mp, n_miss, n_tp, n_dup, repeats, cut FROM calibration "
        "WHERE run_id = ? AND structure = ? ORDER BY rowid");
    s.bind_all(run, structure);
    while (s.step()) {
        CalibrationPoint p{s.text(0), std::uint32_t(s.int64(1)),
                           s.real(2), s.real(3),
                           s.real(4), s.real(5),
                           s.real(6), s.real(7),
                           s.real(8), s.real(9)};
        p.repeats = int(s.int64(10));
        p.cut = s.int64(11) != 0;
        const auto seen = std::find_if(out.begin(), out.end(), [&](const auto& q) { return q.scene == p.scene; });
        if (seen == out.end()) {
            out.push_back(p);
        } else {
            // Counters are the same in every pass (fixed scenes and rays) but where the budget cut one;
            // the point is the fastest pass's, whole.
            const int passes = seen->passes + 1;
            if (p.ns_per_ray < seen->ns_per_ray) *seen = p;
            seen->passes = passes;
        }
    }
    return out;
}

}  // namespace rcb
