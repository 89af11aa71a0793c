#pragma once
/// Checks for numeric command-line options that CLI11's own conversions let through: NaN passes
/// CLI::Range (every comparison with NaN is false), and an unsigned option takes "-1" or a number
/// beyond 2^64 by wrapping or saturating. Both would reach the generators as silent nonsense.

#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>

#include <CLI/CLI.hpp>

#include "analysis/repetitions.h"

namespace rcb {

/// A finite number in [lo, hi].
inline CLI::Validator finite_range(double lo, double hi) {
    return CLI::Validator(
        [lo, hi](std::string& text) -> std::string {
            double v = 0;
            const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
            if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(v) || v < lo || v > hi)
                return "expected a number in " + CLI::detail::to_string(lo) + ".." + CLI::detail::to_string(hi) +
                       ", got " + text;
            return {};
        },
        "NUMBER in " + CLI::detail::to_string(lo) + ".." + CLI::detail::to_string(hi));
}

/// Decimal digits only (no sign, no hex), in [lo, hi].
inline CLI::Validator whole_number(std::uint64_t lo = 0, std::uint64_t hi = std::numeric_limits<std::uint64_t>::max()) {
    return CLI::Validator(
        [lo, hi](std::string& text) -> std::string {
            std::uint64_t v = 0;
            const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
            if (text.empty() || ec != std::errc() || end != text.data() + text.size() || v < lo || v > hi)
                return "expected a whole number in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got " + text;
            return {};
        },
        "UINT");
}

/// An existing regular file to read: not empty, not a folder, and not a device or pipe such as
/// /dev/zero, whose reading would never end.
inline CLI::Validator input_file() {
    return CLI::Validator(
        [](std::string& path) -> std::string {
            if (path.empty()) return "expected a file name, got an empty one";
            std::error_code ec;
            const std::filesystem::file_status st = std::filesystem::status(path, ec);
            if (!std::filesystem::exists(st)) return "no such file: " + path;
            if (std::filesystem::is_directory(st)) return path + " is a folder, not a file";
            if (!std::filesystem::is_regular_file(st)) return path + " is not a regular file";
            return {};
        },
        "FILE");
}

/// A run id as the database numbers them: 1 and up. An explicit 0 is refused, not read as "the
/// newest run" (what leaving the option out means).
inline CLI::Validator run_id() { return whole_number(1, std::uint64_t(std::numeric_limits<std::int64_t>::max())); }

/// A non-empty text (names, folders).
inline CLI::Validator non_empty() {
    return CLI::Validator([](std::string& text) -> std::string { return text.empty() ? "must not be empty" : ""; }, "");
}

/// `--repetitions fastest-cast|fastest|median`: what stands for a cell's repetitions (analysis/repetitions.h).
inline CLI::Option* add_repetitions_option(CLI::App* cmd, OverRepetitions& how) {
    return cmd
        ->add_option_function<std::string>(
            "--repetitions", [&how](const std::string& name) { how = parse_repetitions(name).value(); },
            "What stands for a cell's repetitions: 'fastest-cast' (the default), each frame's fastest ray cast "
            "(another process only ever adds time) and its median update over them (the cache state an update "
            "starts in also takes time away); 'fastest', each frame's fastest of both; or 'median', every "
            "repetition as measured")
        ->check(CLI::IsMember(repetitions_names()))
        ->default_str(repetitions_name(OverRepetitions::fastest_cast));
}

}  // namespace rcb
