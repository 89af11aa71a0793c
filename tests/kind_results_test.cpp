// Query kinds through the pipeline: the simulator's per-kind batches and counts, the database's
// frame_kind (migration, store, merge), the cost model on each kind's counters, the kind-transfer
// validation, another run's model on each kind (validate --test), fit's table per kind and the
// report's "Query kinds" section.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "analysis/cost_model.h"
#include "analysis/model_terms.h"
#include "analysis/query_kinds.h"
#include "analysis/report.h"
#include "core/base/statistics.h"
#include "analysis/validation.h"
#include "accel/model/counter_fields.h"
#include "accel/registry.h"
#include "core/base/number_text.h"
#include "core/base/random.h"
#include "core/scene/generate/generators.h"
#include "sim/simulator.h"
#include "runner/experiment.h"
#include "runner/merge.h"
#include "runner/run_experiment.h"
#include "runner/store.h"
#include "tests/subprocess.h"
#include "tests/test_db.h"
#include "tests/test_scenes.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

/// A generated scene whose frames ask for kinds: frame 1 only closest, frame 2 all three, frame 3
/// all hits (no kinds), the rest all three.
Recording mixed_recording() {
    Recording r = test::generated_scene("irregular", 1500, 6, 21);
    for (std::size_t i = 0; i < r.frames.size(); ++i) {
        Frame& f = r.frames[i];
        if (i == 0)
            f.kinds.assign(f.rays.size(), QueryKind::closest);
        else if (i != 2)
            f.kinds =
                generate_kinds(f.rays.size(), parse_query_mix("closest:0.5,any:0.3,all:0.2"), 9, std::uint32_t(i + 1));
    }
    return r;
}

/// The counting pass of `rays` with `kinds` after replaying the recording's build and changes up to
/// frame `frame` (1-based) on a fresh structure: what the simulator's counting pass must give.
Counters replayed_counts(const Recording& r, const std::string& name, std::size_t frame,
                         const std::vector<Segment>& rays, const std::vector<QueryKind>& kinds) {
    std::unique_ptr<Structure> s = find_structure(name).make(nlohmann::json::object(), "params");
    s->build(r.initial);
    s->commit();
    for (std::size_t i = 0; i < frame; ++i) {
        for (Uid uid : r.frames[i].removes) s->remove(uid);
        for (const Object& o : r.frames[i].inserts) s->insert(o);
        for (const Object& o : r.frames[i].moves) s->move(o);
        s->commit();
    }
    HitLists hits;
    Counters c;
    s->cast_counted(rays, kinds, hits, c);
    return c;
}

TEST(KindResults, PerKindResultsSumToTheFrameAndEachKindIsCountedAsItsOwnBatch) {
    const Recording r = mixed_recording();
    for (const char* name : {"bf", "ug", "dbvh", "lbvh"}) {
        const SimulationResult res = simulate(r, find_structure(name), nlohmann::json::object());
        ASSERT_EQ(res.mismatches(), 0u) << name;
        for (std::size_t i = 0; i < res.frames.size(); ++i) {
            const FrameResult& f = res.frames[i];
            const Frame& frame = r.frames[i];
            if (frame.kinds.empty()) {
                EXPECT_TRUE(f.kinds.empty()) << name;
                continue;
            }
            std::uint32_t rays = 0;
            std::uint64_t ns = 0, wall = 0, cpu = 0, hits = 0;
            Counters sum;
            int previous = -1;
            for (const KindResult& k : f.kinds) {
                EXPECT_GT(int(k.kind), previous) << "kinds in kind order, each once";
                previous = int(k.kind);
                std::vector<Segment> batch;
                for (std::size_t j = 0; j < frame.rays.size(); ++j)
                    if (frame.kinds[j] == k.kind) batch.push_back(frame.rays[j]);
                EXPECT_EQ(k.rays, batch.size()) << name;
                EXPECT_GT(k.raycast_ns, 0u);
                // The kind's counters are those of its rays as a batch of their own.
                EXPECT_EQ(k.counters,
                          replayed_counts(r, name, i + 1, batch, std::vector<QueryKind>(batch.size(), k.kind)))
                    << name << " frame " << f.frame << " " << query_kind_name(k.kind);
                if (k.kind != QueryKind::all) {
                    EXPECT_LE(k.hits, k.rays);
                }
                rays += k.rays, ns += k.raycast_ns, wall += k.raycast.wall_ns, cpu += k.raycast.cpu_ns;
                hits += k.hits, sum += k.counters;
            }
            EXPECT_EQ(rays, f.rays);
            EXPECT_EQ(ns, f.raycast_ns);
            EXPECT_EQ(wall, f.raycast.wall_ns);
            EXPECT_EQ(cpu, f.raycast.cpu_ns);
            EXPECT_EQ(hits, f.hits);
            EXPECT_EQ(sum, f.counters);
            EXPECT_EQ(f.kinds.size(), i == 0 ? 1u : 3u);
        }
        const nlohmann::json j = res.to_json();
        ASSERT_TRUE(j.contains("kinds")) << name;
        EXPECT_EQ(j["kinds"]["frames"].size(), res.frames.size());
        EXPECT_EQ(j["kinds"]["frames"][2].size(), 0u);  // the all-hits frame
        EXPECT_TRUE(j["kinds"]["summary"].contains("any"));
    }
}

TEST(KindResults, AFrameOfOneKindIsCastAndCountedAsOneBatchAsBefore) {
    Recording r = test::generated_scene("uniform", 1200, 3, 4);
    r.frames[0].kinds.assign(r.frames[0].rays.size(), QueryKind::any);
    r.frames[1].kinds.assign(r.frames[1].rays.size(), QueryKind::all);  // one kind, written out
    const SimulationResult res = simulate(r, find_structure("dbvh"), nlohmann::json::object());
    for (std::size_t i = 0; i < 3; ++i) {
        const FrameResult& f = res.frames[i];
        // The whole frame is one batch: its counters are the whole batch's (the history predictor's
        // N_MP runs across every ray), exactly the frame's figures before per-kind batches.
        EXPECT_EQ(f.counters, replayed_counts(r, "dbvh", i + 1, r.frames[i].rays, r.frames[i].kinds));
        EXPECT_EQ(f.any, i == 0 ? f.rays : 0u);
        if (i == 0) {
            ASSERT_EQ(f.kinds.size(), 1u);
            const KindResult& k = f.kinds[0];
            EXPECT_EQ(k.kind, QueryKind::any);
            EXPECT_EQ(k.rays, f.rays);
            EXPECT_EQ(k.raycast_ns, f.raycast_ns);
            EXPECT_EQ(k.raycast.wall_ns, f.raycast.wall_ns);
            EXPECT_EQ(k.hits, f.hits);
            EXPECT_EQ(k.counters, f.counters);
        } else {
            EXPECT_TRUE(f.kinds.empty());  // all hits, whether the kinds are written out or not
        }
    }
    const nlohmann::json j = res.to_json();
    ASSERT_TRUE(j.contains("kinds"));  // the any frame's
    EXPECT_EQ(j["kinds"]["frames"][0].size(), 1u);
    EXPECT_EQ(j["kinds"]["frames"][1].size(), 0u);
}

TEST(KindResults, EveryCounterIsReadThroughTheCoreList) {
    // accel/model/counter_fields.h (kCounterFields) names each counter once: the simulator's JSON (per
    // frame and per kind) and the cost model's observations read it from there.
    Recording r = test::generated_scene("uniform", 1200, 3, 4);
    r.frames[0].kinds.assign(r.frames[0].rays.size(), QueryKind::any);
    const SimulationResult res = simulate(r, find_structure("dbvh"), nlohmann::json::object());
    const nlohmann::json j = res.to_json();
    const FrameResult& f = res.frames[0];
    ASSERT_EQ(f.kinds.size(), 1u);
    ASSERT_GT(f.counters.n_rb, f.counters.n_tp);  // distinct values, so a swapped member shows
    for (const CounterField& c : kCounterFields) {
        ASSERT_TRUE(j.contains(c.name)) << c.name;
        EXPECT_EQ(j[c.name][0], f.counters.*c.member) << c.name;
        EXPECT_EQ(j["kinds"]["frames"][0][0][c.name], f.kinds[0].counters.*c.member) << c.name;
    }
    // Every per-ray counter of the cost model is a core counter: the frame's count per ray.
    const FrameObservation o = observation_of(f, double(res.objects));
    std::size_t per_ray = 0;
    for (const FrameCounter& c : frame_counters()) {
        if (c.scale != CounterScale::per_ray) continue;
        const CounterField* counted = counter_field(c.alias);
        ASSERT_NE(counted, nullptr) << c.alias;
        EXPECT_DOUBLE_EQ(o.*(c.field), double(f.counters.*(counted->member)) / f.rays) << c.alias;
        ++per_ray;
    }
    EXPECT_EQ(per_ray, 7u);  // N_RB, N_T, N_TP, N_RO, N_TH, N_MP, N_MISS
    EXPECT_EQ(o.objects, double(res.objects));
}

// ---------------------------------------------------------------------------------------------
// The database.

using test::count;

TEST(KindResults, FrameKindMigratesIsStoredForFramesWithKindsAndSurvivesMerge) {
    const test::TempDir temp("kinds", "store");
    const std::string a = temp.file("a.db"), b = temp.file("b.db");
    { ResultStore old(a, 10); }  // the schema before frame_kind
    const Experiment e =
        parse_experiment(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "ug"}]})", "kinds", ".");
    const Recording mixed = mixed_recording();
    Recording plain = mixed;
    for (Frame& f : plain.frames) f.kinds.clear();
    const SimulationResult with = simulate(mixed, find_structure("ug"), nlohmann::json::object());
    const SimulationResult without = simulate(plain, find_structure("ug"), nlohmann::json::object());
    {
        ResultStore store(a);  // migrated on open
        EXPECT_EQ(count(store.db(), "PRAGMA user_version"), latest_schema_version());
        EXPECT_EQ(count(store.db(), "SELECT count(*) FROM frame_kind"), 0);
        const std::int64_t ex = store.experiment_id(e);
        const std::int64_t run = store.begin_run(ex, RunInfo::current(1, "", e));
        Cell c = e.plan[0];
        c.key += "mixed";
        ASSERT_TRUE(store.store_cell(run, ex, c, e.scenes[0], mixed, recording_hash(mixed), with));
        c.key += "plain";
        ASSERT_TRUE(store.store_cell(run, ex, c, e.scenes[0], plain, recording_hash(plain), without));
    }
    {
        ResultStore merged(b);
        EXPECT_EQ(merge_into(merged, *open_read_only(a)).cells, 2u);
    }
    const std::string sums =
        "SELECT count(*) FROM frame JOIN cell ON cell.id = frame.cell_id WHERE cell.cell_key LIKE '%mixed' AND "
        "frame.frame != 3 AND (rays, raycast_ns, raycast_wall_ns, hits, n_t, n_rb, n_tp, n_th, n_mp, n_dup) = (SELECT "
        "sum(k.rays), sum(k.raycast_ns), sum(k.raycast_wall_ns), sum(k.hits), sum(k.n_t), sum(k.n_rb), sum(k.n_tp), "
        "sum(k.n_th), sum(k.n_mp), sum(k.n_dup) FROM frame_kind AS k WHERE k.cell_id = frame.cell_id AND k.frame = "
        "frame.frame)";
    // The grid drops hits it met again in a later cell: a kind's n_dup must survive the merge too.
    std::uint64_t dropped = 0;
    for (const FrameResult& f : with.frames)
        for (const KindResult& k : f.kinds) dropped += k.counters.n_dup;
    ASSERT_GT(dropped, 0u);
    for (const std::string& path : {a, b}) {
        auto db = open_read_only(path);
        // Frame 1 has one kind (one row), frame 3 none, the other four frames three each.
        EXPECT_EQ(count(*db, "SELECT count(*) FROM frame_kind"), 1 + 4 * 3) << path;
        EXPECT_EQ(count(*db, "SELECT count(*) FROM frame_kind WHERE frame = 3"), 0) << path;
        EXPECT_EQ(count(*db,
                        "SELECT count(*) FROM frame_kind JOIN cell ON cell.id = frame_kind.cell_id WHERE "
                        "cell.cell_key LIKE '%plain'"),
                  0)
            << "all-hits frames store no kinds";
        EXPECT_EQ(count(*db, sums), 5) << path;  // every frame with kinds: its rows sum to it
        EXPECT_EQ(count(*db, "SELECT rays FROM frame_kind WHERE frame = 1 AND kind = 'closest'"),
                  std::int64_t(mixed.frames[0].rays.size()));
        EXPECT_EQ(count(*db, "SELECT n_mp FROM frame_kind WHERE frame = 4 AND kind = 'any'"),
                  std::int64_t(with.frames[3].kinds[2].counters.n_mp));
    }
}

// ---------------------------------------------------------------------------------------------
// The cost model per kind, on a hand-built run whose times follow eq. 5.4 exactly.

constexpr double kRb = 2, kT = 4, kPrep = 30;

/// A batch's time by eq. 5.4 with the constants above.
std::int64_t batch_ns(std::int64_t rays, std::int64_t n_rb, std::int64_t n_t) {
    return std::int64_t(kPrep) * rays + std::int64_t(kRb) * n_rb + std::int64_t(kT) * n_t;
}

/// One run of structure "tree": 4 scenes × 2 configurations × 8 frames; per frame, with `kinds`,
/// 100 all, 200 closest and 100 any rays with their own integer counts per ray, each kind's time
/// rays × (C_PREP + C_RB·N_RB + C_T·N_T) times the kind's `scale` (1 when absent, rounded to whole
/// ns) and the frame the sums; without, one batch of 400 rays.
void write_hand_run(const std::string& path, bool kinds, const std::map<std::string, double>& scale = {}) {
    const auto measured_ns = [&](const char* kind, std::int64_t ns) {
        const auto it = scale.find(kind);
        return it == scale.end() ? ns : std::int64_t(std::llround(it->second * double(ns)));
    };
    ResultStore store(path);
    Database& db = store.db();
    db.exec(
        "INSERT INTO experiment(name) VALUES ('hand');"
        "INSERT INTO run(uuid, experiment_id, experiment_hash, experiment_content, started_at, git_commit, compiler, "
        "flags, cpu_model, cores, governor, hostname, threads, shard) VALUES ('u', 1, 'h', '{}', 't', 'g', 'c', 'f', "
        "'cpu', 1, 'gov', 'host', 1, '')");
    Random rng(17);
    int cell = 0;
    for (int scene = 0; scene < 4; ++scene) {
        // Named copies, not "h" + std::to_string(scene): GCC 12 inlines that into a false -Wrestrict.
        const std::string index = std::to_string(scene), hash = "h" + index, name = "scene" + index;
        db.prepare(
              "INSERT INTO scene(hash, name, spec, meta, objects, frames, rays_per_frame, stats) VALUES (?, ?, "
              "'{\"kind\": \"irregular\"}', '{}', 1000, 8, 400, '{}')")
            .bind_all(hash, name)
            .run();
        for (int config = 0; config < 2; ++config) {
            db.prepare("INSERT OR IGNORE INTO config(structure, params) VALUES ('tree', ?)")
                .bind(1, "{\"g\":" + std::to_string(config) + "}")
                .run();
            db.prepare(
                  "INSERT INTO cell(run_id, cell_key, scene_id, config_id, repetition, finished_at, objects, build_ns, "
                  "memory_bytes, verified, mismatches, frames, update_ns_median, update_ns_mad, raycast_ns_median, "
                  "raycast_ns_mad) VALUES (1, ?, ?, ?, 0, 't', 1000, 1, 0, 1, 0, 8, 0, 0, 0, 0)")
                .bind_all(std::to_string(++cell), std::int64_t(scene + 1), std::int64_t(config + 1))
                .run();
            for (int frame = 1; frame <= 8; ++frame) {
                struct Batch {
                    const char* kind;
                    std::int64_t rays, n_rb, n_t;
                };
                std::vector<Batch> batches;
                for (auto [kind, rays] : {std::pair{"all", 100}, {"closest", 200}, {"any", 100}})
                    batches.push_back(
                        {kind, rays, rays * std::int64_t(rng.below(400) + 5), rays * std::int64_t(rng.below(300) + 5)});
                std::int64_t rays = 0, n_rb = 0, n_t = 0, ns = 0;
                for (const Batch& k : batches)
                    rays += k.rays, n_rb += k.n_rb, n_t += k.n_t,
                        ns += measured_ns(k.kind, batch_ns(k.rays, k.n_rb, k.n_t));
                const std::int64_t moves = 20 + frame;
                db.prepare(
                      "INSERT INTO frame(cell_id, frame, warmup, inserts, removes, moves, rays, update_ns, raycast_ns, "
                      "hits, missed, extra, duplicate, n_t, n_rb, n_tp, memory_bytes, stats) VALUES (?, ?, 0, 5, 5, "
                      "?, ?, ?, ?, 0, 0, 0, 0, ?, ?, 0, 0, '{}')")
                    .bind_all(std::int64_t(cell), std::int64_t(frame), moves, rays, 500 * moves + 2000, ns, n_t, n_rb)
                    .run();
                for (const Batch& k : batches)
                    if (kinds)
                        db.prepare(kFrameKindInsertSql)
                            .bind_all(std::int64_t(cell), std::int64_t(frame), std::string(k.kind), k.rays,
                                      measured_ns(k.kind, batch_ns(k.rays, k.n_rb, k.n_t)),
                                      measured_ns(k.kind, batch_ns(k.rays, k.n_rb, k.n_t)), std::int64_t(0), k.n_t,
                                      k.n_rb, std::int64_t(0), std::int64_t(0), std::int64_t(0), std::int64_t(0),
                                      std::int64_t(0), std::int64_t(0), std::int64_t(0))
                            .run();
            }
        }
    }
}

TEST(KindModel, EachKindIsPricedByTheRunsCoefficientsOnItsOwnCounters) {
    const test::TempDir temp("kinds", "model");
    write_hand_run(temp.file("k.db"), true);
    Database db(temp.file("k.db"), true);
    ASSERT_TRUE(run_has_frame_kinds(db, 1));
    const std::vector<StructureModels> models = fit_cost_models(load_observations(db, 1));
    ASSERT_EQ(models.size(), 1u);
    const CandidateModel* chosen = models[0].chosen("raycast");
    ASSERT_NE(chosen, nullptr);
    const std::vector<FrameObservation> kind_frames = load_kind_observations(db, 1);
    ASSERT_EQ(kind_frames.size(), 8u * 8 * 3);
    const std::vector<KindCell> cells = kind_cells(models, kind_frames);
    ASSERT_EQ(cells.size(), 8u * 3);
    for (const KindCell& c : cells) {
        // The prediction is the chosen coefficients times the kind's own counters, frame by frame.
        std::vector<double> expected, measured;
        for (const FrameObservation& f : kind_frames) {
            if (f.scene != c.scene || f.params != c.params || f.kind != c.kind) continue;
            double ns = 0;
            for (const Coefficient& k : chosen->fit.coefficients) ns += k.value * term_value(find_term(k.name), f);
            expected.push_back(ns);
            measured.push_back(f.raycast_ns / f.rays);
        }
        ASSERT_EQ(expected.size(), 8u);
        EXPECT_NEAR(c.predicted_ns_per_query, quantile(expected, 0.5), 1e-9 * quantile(expected, 0.5));
        EXPECT_DOUBLE_EQ(c.ns_per_query, quantile(measured, 0.5));
        EXPECT_EQ(c.rays, c.kind == "closest" ? 200.0 : 100.0);
        EXPECT_LT(c.error, 0.02) << c.scene << " " << c.kind;  // times follow eq. 5.4 exactly
    }
    const std::vector<KindError> errors = kind_errors(cells);
    ASSERT_EQ(errors.size(), 3u);
    EXPECT_EQ(errors[0].kind, "all");
    EXPECT_EQ(errors[1].kind, "closest");
    EXPECT_EQ(errors[2].kind, "any");
    for (const KindError& e : errors) EXPECT_EQ(e.cells, 8u);
}

TEST(KindModel, KindTransferExistsWithKindsAndIsAbsentWithout) {
    const test::TempDir temp("kinds", "transfer");
    write_hand_run(temp.file("k.db"), true);
    write_hand_run(temp.file("plain.db"), false);
    {
        Database db(temp.file("k.db"), true);
        const std::vector<FrameObservation> frames = load_kind_observations(db, 1);
        const std::vector<ValidationSplit> splits = kind_transfer_splits(frames);
        ASSERT_EQ(splits.size(), 3u);
        EXPECT_EQ(splits[0].name, "all -> closest");
        EXPECT_EQ(splits[1].name, "all -> any");
        EXPECT_EQ(splits[2].name, "closest+any -> all");
        for (std::size_t i : splits[0].train) EXPECT_EQ(frames[i].kind, "all");
        for (std::size_t i : splits[0].test) EXPECT_EQ(frames[i].kind, "closest");
        const std::vector<ValidationGroup> groups = validate_nested(frames, {}, splits, {50, 1});
        ASSERT_EQ(groups.size(), 1u);
        EXPECT_EQ(groups[0].name, kKindTransferGroup);
        ASSERT_EQ(groups[0].structures.size(), 1u);
        EXPECT_LT(groups[0].structures[0].raycast.median, 1e-3);  // one set of coefficients fits every kind
    }
    {
        Database db(temp.file("plain.db"), true);
        EXPECT_FALSE(run_has_frame_kinds(db, 1));
        const std::vector<FrameObservation> frames = load_kind_observations(db, 1);
        EXPECT_EQ(frames.size(), 8u * 8);
        EXPECT_TRUE(kind_transfer_splits(frames).empty());
    }
    // The command stores the group with kinds and says it is absent without.
    for (const char* name : {"k.db", "plain.db"}) {
        const ::test::Outcome out = ::test::run_process(
            {RCBENCH_BINARY, "validate", "--train", temp.file(name), "--json", "--resamples", "20"});
        ASSERT_EQ(out.code, 0) << out.err;
        const nlohmann::json j = nlohmann::json::parse(out.out);
        bool group = false;
        for (const nlohmann::json& g : j["groups"]) group = group || g["group"] == kKindTransferGroup;
        const bool kinds = std::string(name) == "k.db";
        EXPECT_EQ(group, kinds) << name;
        EXPECT_EQ(j["query_kinds"]["kind_transfer"].get<std::string>().rfind(kinds ? "present" : "absent: ", 0), 0u);
        EXPECT_EQ(j["query_kinds"]["model_per_kind"].size(), kinds ? 3u : 0u);
        Database db(temp.file(name), true);
        EXPECT_EQ(count(db, "SELECT count(*) FROM model_validation WHERE split = 'kind-transfer'"), kinds ? 1 : 0);
    }
}

// ---------------------------------------------------------------------------------------------
// A frozen model on another run's kinds (validate --test) and the fit's table per kind.

/// The test run's closest batches take 1.5 times what eq. 5.4 says and its any batches 0.8 times;
/// a model fitted on a run that follows eq. 5.4 exactly is off by 0.5 / 1.5 and 0.2 / 0.8 on them.
const std::map<std::string, double> kTestScale{{"all", 1.0}, {"closest", 1.5}, {"any", 0.8}};
const std::map<std::string, double> kTestError{{"all", 0.0}, {"closest", 0.5 / 1.5}, {"any", 0.2 / 0.8}};

/// ns per query of `f` by the chosen model's coefficients times its terms, by hand.
double priced(const CandidateModel& m, const FrameObservation& f) {
    double ns = 0;
    for (const Coefficient& k : m.fit.coefficients) ns += k.value * term_value(find_term(k.name), f);
    return ns;
}

TEST(KindModel, AFrozenModelPricesEachKindOfAnotherRunFromItsOwnCounters) {
    const test::TempDir temp("kinds", "frozen");
    write_hand_run(temp.file("a.db"), false);
    write_hand_run(temp.file("b.db"), true, kTestScale);
    Database a(temp.file("a.db"), true), b(temp.file("b.db"), true);
    const std::vector<StructureModels> models = fit_cost_models(load_observations(a, 1));
    ASSERT_EQ(models.size(), 1u);
    const CandidateModel* chosen = models[0].chosen("raycast");
    ASSERT_NE(chosen, nullptr);
    const std::vector<FrameObservation> kind_frames = load_kind_observations(b, 1);
    const std::vector<ValidationGroup> groups = validate_frozen_kinds(models, kind_frames, {200, 5});
    ASSERT_EQ(groups.size(), 3u);
    for (std::size_t i = 0; i < groups.size(); ++i) {
        const ValidationGroup& g = groups[i];
        const std::string kind = kQueryKindNames[i];
        EXPECT_EQ(g.name, std::string(kKindGroupPrefix) + kind);
        EXPECT_EQ(g.splits, std::vector<std::string>{g.name});
        ASSERT_EQ(g.cells.size(), 8u) << kind;
        std::vector<double> errors;
        for (const CellPrediction& c : g.cells) {
            // By hand: per frame of the cell the batch priced from its own counters, and measured.
            std::vector<double> predicted, measured, exact;
            for (const FrameObservation& f : kind_frames) {
                if (f.scene != c.scene || f.params != c.params || f.kind != kind) continue;
                predicted.push_back(priced(*chosen, f) * f.rays);
                measured.push_back(f.raycast_ns);
                exact.push_back(f.rays * (kPrep + kRb * f.n_rb + kT * f.n_t));
            }
            ASSERT_EQ(predicted.size(), 8u);
            const double p = quantile(predicted, 0.5), m = quantile(measured, 0.5);
            EXPECT_NEAR(m, kTestScale.at(kind) * quantile(exact, 0.5), 1.0);  // what was stored
            EXPECT_NEAR(c.predicted_raycast_ns, p, 1e-9 * p);
            EXPECT_DOUBLE_EQ(c.raycast_ns, m);
            EXPECT_NEAR(c.raycast_error, std::abs(p - m) / m, 1e-9);
            EXPECT_NEAR(c.raycast_error, kTestError.at(kind), 0.02) << kind;
            EXPECT_TRUE(std::isnan(c.frame_error));  // a kind's batch has no frame time of its own
            EXPECT_EQ(c.raycast_model, chosen->name);
            errors.push_back(c.raycast_error);
        }
        ASSERT_EQ(g.structures.size(), 1u);
        const StructureValidation& s = g.structures[0];
        EXPECT_EQ(s.structure, "tree");
        EXPECT_EQ(s.cells, 8u);
        EXPECT_EQ(s.scenes, 4u);
        EXPECT_EQ(s.unpredictable, 0u);
        EXPECT_DOUBLE_EQ(s.raycast.median, quantile(errors, 0.5));
        EXPECT_DOUBLE_EQ(s.raycast.p90, quantile(errors, 0.9));
        EXPECT_LE(s.raycast.median_low, s.raycast.median);
        EXPECT_GE(s.raycast.median_high, s.raycast.median);
        EXPECT_TRUE(std::isnan(s.frame.median));
    }

    // The fit's table: per kind the batches, the medians over them of the measured and the priced
    // time per query, and the median over cells of the error.
    const std::vector<KindSummary> rows = kind_summaries(models, kind_frames);
    ASSERT_EQ(rows.size(), 3u);
    for (std::size_t i = 0; i < rows.size(); ++i) {
        const KindSummary& r = rows[i];
        EXPECT_EQ(r.structure, "tree");
        EXPECT_EQ(r.kind, kQueryKindNames[i]);
        std::vector<double> measured, predicted;
        Statement q = b.prepare("SELECT raycast_ns, rays FROM frame_kind WHERE kind = ?");
        q.bind(1, r.kind);
        while (q.step()) measured.push_back(q.real(0) / q.real(1));
        for (const FrameObservation& f : kind_frames)
            if (f.kind == r.kind) predicted.push_back(priced(*chosen, f));
        EXPECT_EQ(r.batches, 64u);
        EXPECT_EQ(r.cells, 8u);
        EXPECT_DOUBLE_EQ(r.ns_per_query, quantile(measured, 0.5));
        EXPECT_NEAR(r.predicted_ns_per_query, quantile(predicted, 0.5), 1e-9 * quantile(predicted, 0.5));
        EXPECT_NEAR(r.median_error, kTestError.at(r.kind), 0.02) << r.kind;
    }
}

/// The words of the first line of `text` whose first words are `start`; empty when none is.
std::vector<std::string> row_starting(const std::string& text, const std::vector<std::string>& start) {
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);) {
        std::istringstream in(line);
        std::vector<std::string> words;
        for (std::string w; in >> w;) words.push_back(w);
        if (words.size() >= start.size() && std::equal(start.begin(), start.end(), words.begin())) return words;
    }
    return {};
}

::test::Outcome rcbench(std::vector<std::string> args) {
    args.insert(args.begin(), RCBENCH_BINARY);
    return ::test::run_process(args);
}

TEST(KindCommands, ValidateTestAndFitShowEachKindAndSayWhenThereIsNone) {
    const test::TempDir temp("kinds", "commands");
    const std::string a = temp.file("a.db"), b = temp.file("b.db");
    write_hand_run(a, false);
    write_hand_run(b, true, kTestScale);
    const std::string kind_rows = "SELECT count(*) FROM model_validation WHERE split LIKE 'kind:%'";

    // The test run has kinds: one group per kind, in the JSON, the text and the test database.
    const ::test::Outcome j = rcbench({"validate", "--train", a, "--test", b, "--json", "--resamples", "20"});
    ASSERT_EQ(j.code, 0) << j.err;
    const nlohmann::json out = nlohmann::json::parse(j.out);
    std::vector<std::string> names;
    for (const nlohmann::json& g : out["groups"]) names.push_back(g["group"].get<std::string>());
    EXPECT_EQ(names,
              (std::vector<std::string>{"transfer", "kind:all", "kind:closest", "kind:any", "calibration-only"}));
    EXPECT_EQ(out["query_kinds"]["per_kind"], "present");
    EXPECT_EQ(out["query_kinds"]["per_kind_groups"], nlohmann::json::array({"kind:all", "kind:closest", "kind:any"}));
    const nlohmann::json& closest = out["groups"][2]["structures"][0];
    EXPECT_EQ(closest["structure"], "tree");
    EXPECT_EQ(closest["cells"], 8);
    EXPECT_NEAR(closest["raycast_error"]["median"].get<double>(), kTestError.at("closest"), 0.02);
    EXPECT_EQ(closest["raycast_error"]["median_ci95"].size(), 2u);
    EXPECT_TRUE(closest["frame_error"]["median"].is_null());
    EXPECT_EQ(out["groups"][2]["cells"].size(), 8u);
    {
        Database db(b, true);
        EXPECT_EQ(count(db, kind_rows + " AND train = '" + a + ":1' AND train_run_uuid = 'u'"), 3);
        Statement s = db.prepare(
            "SELECT raycast_median, frame_median IS NULL FROM model_validation WHERE split = "
            "'kind:any'");
        ASSERT_TRUE(s.step());
        EXPECT_NEAR(s.real(0), kTestError.at("any"), 0.02);
        EXPECT_EQ(s.int64(1), 1);
    }
    const ::test::Outcome t = rcbench({"validate", "--train", a, "--test", b, "--resamples", "20"});
    ASSERT_EQ(t.code, 0) << t.err;
    EXPECT_NE(t.out.find("per query kind (groups kind:KIND)"), std::string::npos) << t.out;
    // The column says what the word means: the query kind, not the scene's generator.
    EXPECT_EQ(row_starting(t.out, {"structure", "query", "kind", "cells"}).size(), 13u) << t.out;
    // "33.3% [33.1, 33.5]" twice (median and p90 with intervals), then the misses and their share.
    EXPECT_EQ(row_starting(t.out, {"tree", "closest", "8", "4"}).size(), 12u) << t.out;
    EXPECT_EQ(t.out.find("absent"), std::string::npos);
    EXPECT_EQ(count(*open_read_only(b), kind_rows), 3) << "stored again: replaced";

    // The test run has none: one line says so, no table, nothing stored.
    const ::test::Outcome n = rcbench({"validate", "--train", b, "--test", a, "--resamples", "20"});
    ASSERT_EQ(n.code, 0) << n.err;
    EXPECT_NE(n.out.find("\nper query kind: absent, the test run has no query kinds"), std::string::npos) << n.out;
    EXPECT_EQ(n.out.find("groups kind:KIND"), std::string::npos);
    EXPECT_EQ(n.out.find("kind:closest"), std::string::npos);
    const ::test::Outcome nj = rcbench({"validate", "--train", b, "--test", a, "--json", "--resamples", "20"});
    ASSERT_EQ(nj.code, 0) << nj.err;
    const nlohmann::json none = nlohmann::json::parse(nj.out);
    EXPECT_EQ(none["groups"].size(), 2u);
    EXPECT_EQ(none["query_kinds"]["per_kind"].get<std::string>().rfind("absent: ", 0), 0u);
    EXPECT_TRUE(none["query_kinds"]["per_kind_groups"].empty());
    EXPECT_EQ(count(*open_read_only(a), kind_rows), 0);

    // fit: the table per kind with kinds, nothing without.
    const ::test::Outcome f = rcbench({"fit", b});
    ASSERT_EQ(f.code, 0) << f.err;
    EXPECT_NE(f.out.find("\nPer query kind: "), std::string::npos) << f.out;
    std::vector<double> per_query;
    {
        Database db(b, true);
        Statement q = db.prepare("SELECT raycast_ns, rays FROM frame_kind WHERE kind = 'closest'");
        while (q.step()) per_query.push_back(q.real(0) / q.real(1));
    }
    const double ns = quantile(per_query, 0.5);
    const std::vector<std::string> row = row_starting(f.out, {"tree", "closest", "64"});
    ASSERT_EQ(row.size(), 6u) << f.out;
    EXPECT_EQ(row_starting(f.out, {"structure", "query", "kind", "batches"}).size(), 9u) << f.out;
    EXPECT_EQ(row[3], fixed(ns / 1e3, ns < 1e3 ? 4 : 3));
    EXPECT_EQ(row[5].back(), '%');
    const ::test::Outcome plain = rcbench({"fit", a});
    ASSERT_EQ(plain.code, 0) << plain.err;
    EXPECT_EQ(plain.out.find("Per query kind"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// The report.

std::string read(const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

TEST(KindReport, QueryKindsSectionAndMotionLinesFromTheRun) {
    const test::TempDir temp("kinds", "report");
    const std::string db_path = temp.file("r.db");
    const Experiment e = parse_experiment(
        R"({"name": "kinds-report", "frames": 4, "rays_per_frame": 150,
            "scenes": [{"generator": "uniform", "name": "mixed", "objects": 1200, "query_mix": "closest:0.4,any:0.3,all:0.3"},
                       {"generator": "uniform", "name": "plain", "objects": 800}],
            "structures": [{"name": "bf"}, {"name": "dbvh"}]})",
        "kinds-report.json", ".");
    RunOptions options;
    options.db = db_path;
    options.new_run = true;
    const std::int64_t run = run_experiment(e, "kinds-report.json", options).run;
    Database db(db_path, true);
    write_report(db, run, temp.file("r.html"));
    const std::string page = read(temp.file("r.html"));
    ASSERT_NE(page.find("<h2>Query kinds</h2>"), std::string::npos);
    EXPECT_EQ(page.find("<td>plain</td><td class=n>bf</td><td class=n>all</td>"), std::string::npos)
        << "a scene without kinds has no rows";
    // dbvh's closest row on the mixed scene: rays per frame and the median time per query, read here
    // from frame_kind.
    Statement s = db.prepare(
        "SELECT frame_kind.rays, frame_kind.raycast_ns FROM frame_kind JOIN frame USING (cell_id, frame) JOIN cell ON "
        "cell.id = frame_kind.cell_id JOIN config ON config.id = cell.config_id WHERE config.structure = 'dbvh' AND "
        "frame_kind.kind = 'closest' AND frame.warmup = 0");
    std::vector<double> rays, per_query;
    while (s.step()) rays.push_back(s.real(0)), per_query.push_back(s.real(1) / s.real(0));
    ASSERT_FALSE(rays.empty());
    const double ns = quantile(per_query, 0.5);
    const std::string row = "<td>mixed</td><td class=n>dbvh</td><td class=n>closest</td><td class=n>" +
                            fixed(quantile(rays, 0.5), 0) + "</td><td class=n>" + fixed(ns / 1e3, ns < 1e3 ? 4 : 3) +
                            "</td>";
    EXPECT_NE(page.find(row), std::string::npos) << row;
    EXPECT_NE(page.find("<td>mixed</td><td class=n>bf</td><td class=n>any</td>"), std::string::npos);
    // All three kinds on the mixed scene: closest and any get a speed-up against all.
    EXPECT_NE(page.find("speed-up against all"), std::string::npos);
    // Motion: every frame of a generated scene changes the same share of its objects.
    Statement m = db.prepare(
        "SELECT 100.0 * (inserts + removes + moves) / scene.objects FROM frame JOIN cell ON cell.id = frame.cell_id "
        "JOIN scene ON scene.id = cell.scene_id WHERE scene.name = 'plain' AND cell.id = (SELECT min(cell.id) FROM "
        "cell JOIN scene ON scene.id = cell.scene_id WHERE scene.name = 'plain')");
    std::vector<double> shares;
    while (m.step()) shares.push_back(m.real(0));
    EXPECT_NE(page.find("Motion on plain: " + fixed(quantile(shares, 0.5), 2) + "% of the objects change per frame"),
              std::string::npos);
    EXPECT_NE(page.find("Motion on mixed: "), std::string::npos);
}

TEST(KindReport, NoQueryKindsSectionWithoutKinds) {
    const test::TempDir temp("kinds", "report_plain");
    write_hand_run(temp.file("plain.db"), false);
    Database db(temp.file("plain.db"), true);
    write_report(db, 1, temp.file("r.html"));
    const std::string page = read(temp.file("r.html"));
    EXPECT_EQ(page.find("Query kinds"), std::string::npos);
    EXPECT_NE(page.find("Motion on scene0: "), std::string::npos);
}

}  // namespace
}  // namespace rcb
