#include "runner/decisions.h"

#include <algorithm>
#include <limits>
#include <map>
#include <tuple>

#include <nlohmann/json.hpp>

#include "core/base/error.h"
#include "sim/simulator.h"
#include "runner/results_reader.h"
#include "runner/run_experiment.h"

namespace rcb {

namespace {

using CellKey = std::tuple<std::string, std::string, std::string>;  // scene hash, structure, params

struct RunCells {
    std::map<std::string, std::string> scene_label;  ///< by scene hash
    std::map<CellKey, double> frame_ns;              ///< per-frame time, update + ray cast
};

/// Every cell's per-frame time in run `run` and its sibling shards, read as the header says: per
/// measured frame the fastest ray cast and the median update over the cell's repetitions, then the
/// median of each over the frames.
RunCells read_cells(Database& db, std::int64_t run) {
    struct Frame {
        double cast = std::numeric_limits<double>::infinity();
        std::vector<double> update;
    };
    RunCells out;
    std::map<std::int64_t, std::string> label_of;  // by scene id
    for (const RunSceneRow& r : read_run_scenes(db, run)) label_of.emplace(r.id, r.label);
    std::map<std::pair<std::int64_t, std::int64_t>, CellKey> key_of;  // by (scene id, config id)
    for (const CellIdentityRow& c : read_cell_identities(db, run)) {
        key_of.emplace(std::pair{c.scene_id, c.config_id}, CellKey{c.scene_hash, c.structure, c.params});
        out.scene_label.emplace(c.scene_hash, label_of.at(c.scene_id));
    }
    std::map<CellKey, std::map<std::int64_t, Frame>> frames;
    for (const FrameTimeRow& r : read_frame_times(db, run)) {
        Frame& f = frames[key_of.at({r.scene_id, r.config_id})][r.frame];
        f.cast = std::min(f.cast, r.raycast_ns);
        f.update.push_back(r.update_ns);
    }
    for (const auto& [key, by_frame] : frames) {
        std::vector<double> cast, update;
        for (const auto& [frame, f] : by_frame) {
            cast.push_back(f.cast);
            update.push_back(spread_of(f.update).median);
        }
        out.frame_ns[key] = spread_of(cast).median + spread_of(update).median;
    }
    return out;
}

/// A configuration as tables show it: the structure and the parameters that differ from its
/// defaults (config_label); the stored parameters in full for a structure this build does not know.
std::string configuration_label(const std::string& structure, const std::string& params) {
    const nlohmann::json j = nlohmann::json::parse(params, nullptr, false);
    try {
        if (!j.is_discarded()) return config_label({structure, j});
    } catch (const std::exception&) {
        // An unknown structure (a database from another build): fall through to the raw text.
    }
    return structure + " " + params;
}

/// The decision over `candidates`, each with its time in run A and in run B (both finite, > 0).
Decision decide(const std::map<std::string, std::pair<double, double>>& candidates, double tie) {
    Decision d;
    d.candidates = candidates.size();
    const auto best = [&](bool in_a) {
        return std::min_element(candidates.begin(), candidates.end(),
                                [&](const auto& x, const auto& y) {
                                    return (in_a ? x.second.first : x.second.second) <
                                           (in_a ? y.second.first : y.second.second);
                                })
            ->first;
    };
    d.pick_a = best(true);
    d.pick_b = best(false);
    const auto& a = candidates.at(d.pick_a);
    const auto& b = candidates.at(d.pick_b);
    d.gap_a = b.first / a.first - 1;
    d.gap_b = a.second / b.second - 1;
    d.verdict = d.pick_a == d.pick_b ? "same" : d.gap_a <= tie && d.gap_b <= tie ? "tie" : "differ";
    return d;
}

}  // namespace

Decisions compare_decisions(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b, double tie) {
    const RunCells x = read_cells(a, run_a), y = read_cells(b, run_b);
    Decisions out;
    out.tie = tie;
    // Per scene: each structure's best configuration in each run (its time there); per (scene,
    // structure): each configuration's time in each run.
    using Times = std::map<std::string, std::pair<double, double>>;
    std::map<std::string, Times> structures;                              // by scene hash
    std::map<std::pair<std::string, std::string>, Times> configurations;  // by (scene hash, structure)
    for (const auto& [key, ta] : x.frame_ns) {
        const auto it = y.frame_ns.find(key);
        if (it == y.frame_ns.end() || !(ta > 0) || !(it->second > 0)) continue;
        const auto& [hash, structure, params] = key;
        ++out.shared_cells;
        configurations[{hash, structure}][configuration_label(structure, params)] = {ta, it->second};
        auto [s, fresh] = structures[hash].try_emplace(structure, ta, it->second);
        if (!fresh) s->second = {std::min(s->second.first, ta), std::min(s->second.second, it->second)};
    }
    if (out.shared_cells == 0)
        throw InputError("the two runs share no measured scene and configuration (scenes are matched by content)");
    for (const auto& [hash, times] : structures) {
        if (times.size() < 2) continue;
        Decision d = decide(times, tie);
        d.scene = x.scene_label.at(hash);
        out.structures.push_back(std::move(d));
    }
    for (const auto& [scene_structure, times] : configurations) {
        if (times.size() < 2) continue;
        Decision d = decide(times, tie);
        d.scene = x.scene_label.at(scene_structure.first);
        d.structure = scene_structure.second;
        out.configurations.push_back(std::move(d));
    }
    const auto by_scene = [](const Decision& p, const Decision& q) {
        return std::tie(p.scene, p.structure) < std::tie(q.scene, q.structure);
    };
    std::sort(out.structures.begin(), out.structures.end(), by_scene);
    std::sort(out.configurations.begin(), out.configurations.end(), by_scene);
    return out;
}

std::pair<std::size_t, std::size_t> agreement(const std::vector<Decision>& d) {
    std::pair<std::size_t, std::size_t> n{0, 0};
    for (const Decision& x : d) {
        n.first += x.verdict == "same";
        n.second += x.verdict != "differ";
    }
    return n;
}

}  // namespace rcb
