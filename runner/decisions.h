#pragma once
/// Whether two runs make the same decisions: per scene the best structure, per (scene, structure)
/// the best configuration. What a user of rcbench repeats is the choice, not the time: two runs on a
/// shared host may differ by several percent per cell and still pick alike (Hoefler and Belli,
/// "Scientific benchmarking of parallel computing systems", SC 2015: report what the conclusion
/// rests on and whether it holds across runs).
///
/// A cell's figure is its per-frame time, update + ray cast, read as `fit`, `validate` and
/// `findings` read it by default ("fastest-cast", analysis/repetitions.h): the median over the
/// measured frames of each frame's fastest ray cast over the cell's repetitions, plus the median
/// over the frames of each frame's median update over them. Two picks that differ tie when each run's
/// own data put the other run's pick within `tie` of its own; otherwise the gap is what choosing the
/// other run's pick would cost in each run's data.

#include <cstdint>
#include <string>
#include <vector>

#include "runner/sqlite.h"

namespace rcb {

/// One decision both runs made: the best of the candidates they share.
struct Decision {
    std::string scene;      ///< the scene's label (kSceneLabelSql) in the first run's database
    std::string structure;  ///< the structure whose configurations are compared; empty for a scene's best structure
    std::size_t candidates = 0;  ///< structures (or configurations) both runs measured on the scene
    std::string pick_a, pick_b;  ///< each run's best: a structure, or a configuration's label
    /// The fractions by which run A's data put B's pick above A's own (pick_a's time in A), and run
    /// B's data A's pick above B's; 0 where the picks agree.
    double gap_a = 0, gap_b = 0;
    /// "same", "tie" (the picks differ, both gaps at most the tie) or "differ".
    std::string verdict;
};

struct Decisions {
    double tie = 0.05;
    std::vector<Decision> structures;      ///< one per scene with two or more shared structures
    std::vector<Decision> configurations;  ///< one per (scene, structure) with two or more shared configurations
    std::size_t shared_cells = 0;          ///< (scene, configuration) cells both runs measured
};

/// The decisions of run `run_a` of `a` and run `run_b` of `b` (each with its sibling shards,
/// kRunGroupSql), over the cells both measured: scenes matched by content hash, configurations by
/// structure and parameters. InputError when they share no cell.
Decisions compare_decisions(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b, double tie);

/// How many decisions of `d` have the verdict "same", and how many "same" or "tie".
std::pair<std::size_t, std::size_t> agreement(const std::vector<Decision>& d);

}  // namespace rcb
