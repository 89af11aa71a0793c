#pragma once
/// Tests on real data (Debian's OpenArena maps and assimp test models, fetched by
/// scripts/fetch_maps.sh) and on real tools (Debian's chromium) skip where those are missing, so
/// the suite runs on any machine; with RCB_REQUIRE_REAL_DATA set (CI sets it) they fail instead,
/// so CI can never pass by skipping them.

#include <gtest/gtest.h>

#include <cstdlib>

#define RCB_REQUIRE_REAL_DATA(present, what)                                                               \
    do {                                                                                                   \
        if (!(present)) {                                                                                  \
            if (std::getenv("RCB_REQUIRE_REAL_DATA")) FAIL() << what << " (RCB_REQUIRE_REAL_DATA is set)"; \
            GTEST_SKIP() << what;                                                                          \
        }                                                                                                  \
    } while (false)
