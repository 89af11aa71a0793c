#pragma once
/// The thesis' conclusions (Guo & Liao 2023, §6.2–§6.4 and chapter 8) checked against one run:
/// for each, whether rcbench's measurements confirm or refute it on the run's scenes, with the
/// figures and counters that say why. Every verdict and sentence is computed from the data; a claim
/// the run cannot test (no uniform scene, no full-SAH DBVH, no fit) says what is missing.

#include <cstdint>
#include <string>
#include <vector>

#include "runner/sqlite.h"

namespace rcb {

struct Finding {
    enum class Verdict { confirmed, partly, refuted, untested };
    std::string claim;   ///< the thesis' conclusion, in a sentence
    std::string source;  ///< where the thesis says it, e.g. "§6.3, Table 6.2"
    Verdict verdict = Verdict::untested;
    std::string summary;                ///< one sentence: the verdict and the deciding figures
    std::vector<std::string> evidence;  ///< one line per scene or structure, with counters
};

const char* verdict_name(Finding::Verdict v);

/// The structures the findings compare: every registered structure that is not another library's
/// (Origin::peer), in registry order. Claims about "the other structures" or "every grid" read
/// this list filtered by family; claims about a named structure name it.
std::vector<std::string> findings_structures();

/// The findings for a run (and its sibling shards). Structures compared are findings_structures(),
/// each at its fastest configuration per scene; per-frame cost = update + ray cast per frame
/// (thesis eq. 5.5), medians over repetitions.
std::vector<Finding> evaluate_findings(Database& db, std::int64_t run);

/// The findings as Markdown (the source of docs/findings.md), headed by the run's provenance.
std::string findings_markdown(Database& db, std::int64_t run, const std::vector<Finding>& findings);

}  // namespace rcb
