#include "analysis/noise.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <map>

#include "core/base/number_text.h"
#include "sim/simulator.h"
#include "runner/run_experiment.h"
#include "runner/results_reader.h"

namespace rcb {

namespace {

/// Every value a time that can be compared: a damaged database can hold anything.
bool all_finite_positive(const std::vector<double>& values) {
    return std::all_of(values.begin(), values.end(), [](double v) { return std::isfinite(v) && v > 0; });
}

}  // namespace

std::vector<StructureNoise> repeatability(const std::vector<RepeatSample>& samples) {
    // structure → cell → repetitions
    std::map<std::string, std::map<std::string, std::vector<const RepeatSample*>>> by;
    for (const RepeatSample& s : samples) by[s.structure][s.cell].push_back(&s);
    std::vector<StructureNoise> out;
    for (const auto& [structure, cells] : by) {
        StructureNoise n;
        n.structure = structure;
        std::vector<double> cast, update, frame;
        for (const auto& [cell, reps] : cells) {
            for (const RepeatSample* r : reps) n.slow += r->slow;
            if (reps.size() < 2) continue;
            ++n.cells;
            n.repetitions += reps.size();
            std::vector<double> c, u, f;
            for (const RepeatSample* r : reps)
                if (r->repetition < 2)
                    c.push_back(r->raycast_ns), u.push_back(r->update_ns), f.push_back(r->raycast_ns + r->update_ns);
            if (c.size() < 2) continue;
            // Only finite spreads count.
            auto add = [](std::vector<double>& to, const std::vector<double>& values) {
                if (all_finite_positive(values)) to.push_back(relative_range(values));
            };
            add(cast, c);
            add(update, u);
            add(frame, f);
        }
        n.raycast = quantile(cast, 0.5);
        n.raycast_p90 = quantile(cast, 0.9);
        n.update = quantile(update, 0.5);
        n.update_p90 = quantile(update, 0.9);
        n.frame = quantile(frame, 0.5);
        n.frame_p90 = quantile(frame, 0.9);
        out.push_back(n);
    }
    return out;
}

const StructureNoise* NoiseFloor::find(const std::string& structure) const {
    for (const StructureNoise& s : structures)
        if (s.structure == structure) return &s;
    return nullptr;
}

NoiseFloor noise_floor(Database& db, std::int64_t run) {
    NoiseFloor out;
    std::vector<RepeatSample> samples;
    std::vector<double> load, calibration;
    for (const CellStateRow& c : read_cell_states(db, run)) {
        RepeatSample r;
        r.structure = c.structure;
        r.cell = std::to_string(c.scene_id) + ":" + std::to_string(c.config_id);
        r.raycast_ns = c.raycast_ns_median;
        r.update_ns = c.update_ns_median;
        r.repetition = c.repetition;
        ++out.cells;
        if (c.has_state) {  // cells of runs made before the machine state have none
            r.slow = c.slow;
            out.slow += r.slow;
            ++out.with_state;
            if (c.load_1m >= 0 && std::isfinite(c.load_1m)) load.push_back(c.load_1m);
            if (std::isfinite(c.calibration_ns)) calibration.push_back(c.calibration_ns);
        }
        samples.push_back(std::move(r));
    }
    out.structures = repeatability(samples);
    if (!load.empty()) out.load_median = spread_of(load).median;
    if (!calibration.empty()) out.calibration_median_ns = spread_of(calibration).median;
    return out;
}

namespace {

/// Per (structure, scene hash, params): the run's figure of the cell (`how`); `slow` counts each
/// key's repetitions flagged slow.
std::map<std::string, std::pair<double, double>> run_medians(Database& db, std::int64_t run, OverRepetitions how,
                                                             std::map<std::string, std::string>& structure_of,
                                                             std::map<std::string, std::size_t>& slow) {
    const std::vector<CellIdentityRow> cells = read_cell_identities(db, run);
    const auto figures = cell_figures(db, run, how);
    std::map<std::string, std::pair<double, double>> out;
    for (const CellIdentityRow& c : cells) {
        const std::string key = c.structure + '\n' + c.scene_hash + '\n' + c.params;
        structure_of[key] = c.structure;
        slow[key] += c.slow;
        const CellFigure& f = figures.at({c.scene_id, c.config_id});
        out[key] = {f.raycast_ns, f.update_ns};
    }
    return out;
}

/// Each run's figure of a cell as one "repetition" of it: repeatability's spread of two is then the
/// relative range of the runs. `pooled`: every cell under the one structure "all".
std::vector<RepeatSample> between_samples(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                          OverRepetitions how, bool pooled) {
    std::map<std::string, std::string> structure_of;
    std::map<std::string, std::size_t> slow;
    const auto in_a = run_medians(a, run_a, how, structure_of, slow);
    const auto in_b = run_medians(b, run_b, how, structure_of, slow);
    std::vector<RepeatSample> samples;
    for (const auto& [key, ma] : in_a) {
        const auto mb = in_b.find(key);
        if (mb == in_b.end()) continue;
        const std::string structure = pooled ? "all" : structure_of[key];
        samples.push_back({structure, key, ma.first, ma.second, slow[key] > 0, 0});
        samples.push_back({structure, key, mb->second.first, mb->second.second, false, 1});
    }
    return samples;
}

}  // namespace

std::vector<StructureNoise> between_runs(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                         OverRepetitions how) {
    return repeatability(between_samples(a, run_a, b, run_b, how, false));
}

StructureNoise between_runs_pooled(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                   OverRepetitions how) {
    const std::vector<StructureNoise> all = repeatability(between_samples(a, run_a, b, run_b, how, true));
    if (!all.empty()) return all.front();
    StructureNoise none;
    none.structure = "all";
    return none;
}

std::vector<UpdateBand> between_runs_by_update(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                               OverRepetitions how) {
    const double edges[] = {0, 10e3, 30e3, 100e3, INFINITY};
    constexpr std::size_t kBands = std::size(edges) - 1;
    std::vector<double> range[kBands], share[kBands];
    // between_samples gives each cell both runs hold as two samples in a row, run a's first.
    const std::vector<RepeatSample> samples = between_samples(a, run_a, b, run_b, how, true);
    for (std::size_t i = 0; i + 1 < samples.size(); i += 2) {
        const RepeatSample &x = samples[i], &y = samples[i + 1];
        if (!all_finite_positive({x.update_ns, y.update_ns, x.raycast_ns, y.raycast_ns})) continue;
        const double size = std::sqrt(x.update_ns * y.update_ns);
        const std::size_t band = std::size_t(std::upper_bound(std::begin(edges), std::end(edges), size) - edges) - 1;
        range[band].push_back(relative_range({x.update_ns, y.update_ns}));
        share[band].push_back((x.update_ns + y.update_ns) / (x.update_ns + y.update_ns + x.raycast_ns + y.raycast_ns));
    }
    std::vector<UpdateBand> out;
    for (std::size_t k = 0; k < kBands; ++k)
        out.push_back({edges[k], edges[k + 1], range[k].size(), quantile(range[k], 0.5), quantile(range[k], 0.9),
                       quantile(share[k], 0.5)});
    return out;
}

std::vector<SlowCell> slow_cells(Database& db, std::int64_t run) {
    std::vector<SlowCell> out;
    // The ratio is against the median of the cell's own run (each shard has its own machine).
    std::map<std::int64_t, double> medians;
    {
        std::map<std::int64_t, std::vector<double>> times;
        for (const CellCalibrationRow& c : read_cell_calibrations(db, run)) times[c.run_id].push_back(c.calibration_ns);
        for (auto& [r, t] : times) medians[r] = spread_of(t).median;
    }
    for (const SlowCellRow& c : read_slow_cells(db, run)) {
        const double median = medians[c.run_id];
        out.push_back(
            {c.scene, c.structure, c.params, c.repetition, c.load_1m, median > 0 ? c.calibration_ns / median : NAN});
    }
    return out;
}

std::string noise_text(double p50, double p90) {
    return std::isfinite(p50) ? noise_text(p50) + " / " + noise_text(p90) : "-";
}

std::string noise_text(double deviation) { return std::isfinite(deviation) ? fixed(100 * deviation, 1) + "%" : "-"; }

}  // namespace rcb
