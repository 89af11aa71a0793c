#include "tuner/accuracy.h"

#include <charconv>
#include <cmath>

#include "core/base/error.h"
#include "core/base/number_text.h"

namespace rcb {

bool AccuracyConstraint::met_by(const MeasuredAccuracy& a) const {
    switch (kind) {
        case Kind::exact:
            return a.exact_level && a.mismatches == 0;
        case Kind::recall:
            return a.verified && a.recall >= bound;
        case Kind::precision:
            return a.verified && a.precision >= bound;
    }
    return false;
}

std::string AccuracyConstraint::text() const {
    if (kind == Kind::exact) return "exact";
    std::string number = fixed(bound, 6);
    while (number.size() > 1 && number.back() == '0') number.pop_back();
    if (number.back() == '.') number.pop_back();
    return std::string(kind == Kind::recall ? "recall" : "precision") + ">=" + number;
}

AccuracyConstraint parse_accuracy(const std::string& text, const std::string& where) {
    AccuracyConstraint c;
    if (text == "exact") return c;
    const auto fail = [&](const std::string& why) {
        throw InputError(where + ": " + why + " (expected exact, recall>=R or precision>=P with R, P in 0..1)");
    };
    const std::size_t op = text.find(">=");
    if (op == std::string::npos) fail("\"" + text + "\" is not a constraint");
    const std::string name = text.substr(0, op), number = text.substr(op + 2);
    if (name == "recall")
        c.kind = AccuracyConstraint::Kind::recall;
    else if (name == "precision")
        c.kind = AccuracyConstraint::Kind::precision;
    else
        fail("unknown measure \"" + name + "\"");
    double v = 0;
    const auto [end, ec] = std::from_chars(number.data(), number.data() + number.size(), v);
    if (number.empty() || ec != std::errc() || end != number.data() + number.size() || !std::isfinite(v))
        fail("\"" + number + "\" is not a number");
    if (v < 0 || v > 1) fail(name + " " + number + " is outside 0..1");
    c.bound = v;
    return c;
}

}  // namespace rcb
