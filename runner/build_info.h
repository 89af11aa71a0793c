#pragma once
/// What built this binary: recorded with every run so results name the code and flags behind them.

namespace rcb {

extern const char* const kGitCommit;     ///< `git describe --always --dirty` of the source at build time
extern const char* const kCompiler;      ///< compiler id and version
extern const char* const kCompileFlags;  ///< the C++ flags of the build type, including -march

}  // namespace rcb
