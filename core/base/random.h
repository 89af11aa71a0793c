#pragma once
/// Seeded randomness with fixed arithmetic. std::mt19937_64's sequence is fixed by the C++
/// standard, but the standard distributions are not (libstdc++ and libc++ differ), so the
/// distributions are written here: the same seed gives the same bytes on every platform.

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <utility>
#include <vector>

#include "core/base/geometry.h"

namespace rcb {

/// SplitMix64's finaliser: derives independent stream seeds from (seed, stream).
constexpr std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t stream) {
    std::uint64_t z = seed + 0x9e3779b97f4a7c15ULL * (stream + 1);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

class Random {
public:
    explicit Random(std::uint64_t seed) : engine_(seed) {}

    /// Uniform in [0, 1) with 53 random bits.
    double uniform() { return double(engine_() >> 11) * 0x1.0p-53; }
    double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
    /// log-uniform in [lo, hi], lo > 0: every order of magnitude equally likely.
    double log_uniform(double lo, double hi) { return lo * std::exp(std::log(hi / lo) * uniform()); }
    /// Uniform integer in [0, n), n > 0, without modulo bias (rejection).
    std::uint64_t below(std::uint64_t n) {
        const std::uint64_t limit = ~std::uint64_t(0) - (~std::uint64_t(0) % n);
        std::uint64_t x;
        do x = engine_();
        while (x >= limit);
        return x % n;
    }
    /// Fisher–Yates with below(): the same order for a seed on every standard library.
    template <typename T>
    void shuffle(std::vector<T>& v) {
        for (std::size_t i = v.size(); i > 1; --i) std::swap(v[i - 1], v[std::size_t(below(i))]);
    }
    /// Standard normal (Box–Muller).
    double normal() {
        double u1 = 1.0 - uniform();  // (0, 1]
        double u2 = uniform();
        return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
    }
    /// Uniform direction on the unit sphere (Archimedes: z uniform, angle uniform).
    Vec3d direction() {
        double z = uniform(-1.0, 1.0);
        double phi = 2.0 * std::numbers::pi * uniform();
        double r = std::sqrt(std::max(0.0, 1.0 - z * z));
        return {r * std::cos(phi), r * std::sin(phi), z};
    }

private:
    std::mt19937_64 engine_;
};

}  // namespace rcb
