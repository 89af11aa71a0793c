#pragma once
/// The thesis' conclusions (Guo & Liao 2023, §6.2–§6.4 and chapter 8) checked against one run or
/// several independent runs of one experiment: for each, whether rcbench's measurements confirm or
/// refute it on the runs' scenes, with the figures and counters that say why, and whether every run
/// alone gives the same verdict. Every verdict and sentence is computed from the data; a claim the
/// runs cannot test (no uniform scene, no full-SAH DBVH, no fit) says what is missing.
/// Scenes are listed smallest first, each scene's structures as findings_structures() lists them,
/// whatever order the run measured its cells in.

#include <cstdint>
#include <string>
#include <vector>

#include "analysis/repetitions.h"
#include "runner/results_reader.h"

namespace rcb {

struct Finding {
    enum class Verdict { confirmed, partly, refuted, untested };
    std::string claim;   ///< the thesis' conclusion, in a sentence
    std::string source;  ///< where the thesis says it, e.g. "§6.3, Table 6.2"
    Verdict verdict = Verdict::untested;
    std::string summary;                ///< one sentence: the verdict and the deciding figures
    std::vector<std::string> evidence;  ///< one line per scene or structure, with counters
    std::vector<Verdict> per_run;       ///< the verdict on each run alone, in the order the runs were given
};

/// A run the findings read: a database and a run id in it (with its sibling shards).
struct FindingsRun {
    Database* db = nullptr;
    std::int64_t run = 0;
};

const char* verdict_name(Finding::Verdict v);

/// The structures the findings compare: every registered structure that is not another library's
/// (Origin::peer), in registry order. Claims about "the other structures" or "every grid" read
/// this list filtered by family; claims about a named structure name it.
std::vector<std::string> findings_structures();

/// The findings over independent runs of one experiment. Structures compared are
/// findings_structures(), each at its fastest measured configuration per scene; per-frame cost =
/// update + ray cast per frame (thesis eq. 5.5). Per run a configuration's figure is its cell figure
/// over the run's repetitions (`how`, analysis/repetitions.h); over runs, the median of those, with
/// their range. The verdict is read on the medians over runs, and again on each run alone
/// (Finding::per_run). Claims of Table 6.2 read the scenes without dense rays; those of Tables 6.3
/// and 6.4 read the dense-ray scenes where the runs have some (the thesis cast dense rays there,
/// §6.4). Traversal costs are compared under one form for every structure, eq. 5.4 as `rcbench fit`
/// stored it, not each structure's chosen form.
std::vector<Finding> evaluate_findings(const std::vector<FindingsRun>& runs,
                                       OverRepetitions how = OverRepetitions::fastest_cast);
std::vector<Finding> evaluate_findings(Database& db, std::int64_t run,
                                       OverRepetitions how = OverRepetitions::fastest_cast);

/// The findings of `runs` (evaluate_findings) as Markdown (the source of docs/findings.md), headed by
/// the runs' provenance and the configurations they measured; the runs are read once.
std::string findings_markdown(const std::vector<FindingsRun>& runs,
                              OverRepetitions how = OverRepetitions::fastest_cast);

}  // namespace rcb
