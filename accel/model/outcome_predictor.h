#pragma once
/// A model of how predictable a traversal is, for the cost model's coherence term.
///
/// A traversal step's cost depends on whether the CPU guessed its branches: consecutive rays that
/// take the same path through a structure (coherent rays, e.g. all aimed at one region) replay the
/// same outcomes, and a history-based branch predictor (TAGE, Seznec & Michaud 2006) learns them,
/// while rays in random directions do not. The same rays also find the same nodes in the L1 cache.
/// The counting pass feeds each step's outcome (node boxes hit, object boxes tested and hit since
/// the last step; for a grid also the plane its 3D-DDA leaves the cell through) to a small tagged
/// predictor with four global-history lengths, and counts the outcomes it fails to predict: N_MP,
/// a machine-independent count of what a ray cannot reuse from the ray before it. Deterministic;
/// the cost model prices it (C_MP, docs/model.md).

#include <array>
#include <cstdint>
#include <vector>

namespace rcb {

class OutcomePredictor {
public:
    OutcomePredictor() : tables_(kTables * kEntries) {}

    /// A step starts; the counters' running sums (node boxes hit, object boxes tested, objects
    /// reported) close the step before, whose outcome is their change since it started.
    void next_step(std::uint64_t n_th, std::uint64_t n_rb, std::uint64_t n_tp) {
        end(n_th, n_rb, n_tp);
        at_ = {n_th, n_rb, n_tp}, open_ = true;
    }
    /// A branch the open step takes that its counts do not show (a grid's 3D-DDA: the plane it
    /// leaves the cell through, or the segment's end), `bits` in 1..7; part of the step's outcome.
    void branch(std::uint32_t bits) {
        if (open_) extra_ = (extra_ << 3 | bits) & 0xffffu;
    }
    /// The batch ends: the open step's outcome is known.
    void end(std::uint64_t n_th, std::uint64_t n_rb, std::uint64_t n_tp) {
        if (!open_) return;
        auto cap = [](std::uint64_t v, std::uint64_t most) { return std::uint32_t(v < most ? v : most); };
        step(cap(n_th - at_[0], 15) | cap(n_rb - at_[1], 63) << 4 | cap(n_tp - at_[2], 63) << 10 | extra_ << 16);
        open_ = false;
        extra_ = 0;
    }
    std::uint64_t mispredicted() const { return mispredicted_; }

private:
    /// One step's outcome; counts a misprediction when the predictor guessed another.
    void step(std::uint32_t outcome) {
        std::uint32_t predicted = last_outcome_;  // base prediction: the previous outcome
        std::array<std::uint32_t, kTables> index{}, tag{};
        for (int t = kTables - 1; t >= 0; --t) {
            const std::uint64_t h = history_hash(kLengths[std::size_t(t)]);
            index[std::size_t(t)] = std::uint32_t(h) & (kEntries - 1);
            tag[std::size_t(t)] = std::uint32_t(h >> 32) | 1u;
        }
        for (int t = kTables - 1; t >= 0; --t) {
            const Entry& e = tables_[std::size_t(t) * kEntries + index[std::size_t(t)]];
            if (e.tag == tag[std::size_t(t)]) {
                predicted = e.outcome;
                break;
            }
        }
        if (predicted != outcome) ++mispredicted_;
        for (int t = 0; t < kTables; ++t)
            tables_[std::size_t(t) * kEntries + index[std::size_t(t)]] = {tag[std::size_t(t)], outcome};
        history_[head_ = (head_ + 1) % kHistory] = outcome;
        last_outcome_ = outcome;
    }

    static constexpr int kTables = 4;
    static constexpr std::uint32_t kEntries = 1u << 12;
    static constexpr std::array<int, kTables> kLengths{2, 6, 16, 40};
    static constexpr int kHistory = 64;
    struct Entry {
        std::uint32_t tag = 0;
        std::uint32_t outcome = 0;
    };

    std::uint64_t history_hash(int length) const {
        std::uint64_t h = 0x9e3779b97f4a7c15ull * std::uint64_t(length);
        for (int i = 0; i < length; ++i) {
            h ^= history_[std::size_t((head_ + kHistory - i) % kHistory)] + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2);
            h *= 0xff51afd7ed558ccdull;
        }
        return h ^ (h >> 29);
    }

    std::vector<Entry> tables_;
    std::array<std::uint32_t, kHistory> history_{};
    int head_ = 0;
    std::uint32_t last_outcome_ = 0, extra_ = 0;
    std::uint64_t mispredicted_ = 0;
    std::array<std::uint64_t, 3> at_{};
    bool open_ = false;
};

}  // namespace rcb
