#pragma once
/// What a tuned or advised configuration must answer: the accuracy constraint of `rcbench tune`
/// and `rcbench advise` (--accuracy). Speed is traded for accuracy only when the user allows it.
///
///     exact          the answer is what the configuration's level promises, nothing more or less:
///                    no mismatches against its contract (core/truth/ground_truth.h) and a level that
///                    promises both sides (boxes or shapes; candidates promise no upper side)
///     recall>=R      correct / relevant against the shapes' truth at least R on every scene
///     precision>=P   correct / returned against the shapes' truth at least P on every scene
///
/// The thesis measures speed only at the exact box level (§6); the query levels of
/// accel/narrow/narrow_phase.h make the broad phase's candidates and the narrow phase choices with a cost
/// and an accuracy (eq. 5.2–5.3), and these constraints say which of them a caller accepts.

#include <cstdint>
#include <string>

namespace rcb {

/// Accuracy of one configuration on a set of scenes.
struct MeasuredAccuracy {
    bool verified = false;             ///< measured against the ground truth (else only the level is known)
    bool exact_level = true;           ///< its query level promises both sides (not candidates)
    std::uint64_t mismatches = 0;      ///< against its own contract, summed over the scenes
    double precision = 1, recall = 1;  ///< the lowest over the scenes (each pooled over its frames)
};

struct AccuracyConstraint {
    enum class Kind { exact, recall, precision } kind = Kind::exact;
    double bound = 1;  ///< R or P; 1 for exact

    /// Whether answers other than exact are acceptable: then the query level is worth searching.
    bool allows_inexact() const { return kind != Kind::exact; }
    /// Whether a configuration needs verifying to be judged (exact judges a boxes- or shapes-level
    /// configuration by its contract, which the test suite verifies for every structure).
    bool needs_verification() const { return kind != Kind::exact; }
    bool met_by(const MeasuredAccuracy& a) const;
    /// "exact", "recall>=0.9", "precision>=0.5"
    std::string text() const;
};

/// Parses `exact`, `recall>=R` or `precision>=P` (R, P finite numbers in 0..1); InputError naming
/// `where` otherwise.
AccuracyConstraint parse_accuracy(const std::string& text, const std::string& where = "--accuracy");

}  // namespace rcb
