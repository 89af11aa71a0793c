#pragma once
/// Errors carry their context (file, line or JSON path, frame, uid) in the message, so the CLI can
/// print one line. `InputError` is the user's input being wrong (exit 2); anything else is a
/// failure of ours or of the machine (exit 1).

#include <stdexcept>
#include <string>

namespace rcb {

class InputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

}  // namespace rcb
