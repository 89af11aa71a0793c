// Users' JSON: a nesting limit at parse time, short excerpts in messages.
#include <gtest/gtest.h>

#include <string>

#include "core/base/error.h"
#include "core/base/json_input.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

std::string error_of(const std::string& text) {
    return test::input_error_of([&] { parse_json_document(text, "f.json"); });
}

TEST(JsonInput, DeepNestingIsRefusedNotACrash) {
    const std::string deep = std::string(50000, '[') + std::string(50000, ']');
    EXPECT_EQ(error_of(deep), "f.json: [0][0][0][0][0][0][0][0]...: JSON nests deeper than 64 levels");
    const std::string objects = [] {
        std::string s;
        for (int i = 0; i < 50000; ++i) s += "{\"a\":";
        return s + "1" + std::string(50000, '}');
    }();
    EXPECT_EQ(error_of(objects), "f.json: a.a.a.a.a.a.a.a...: JSON nests deeper than 64 levels");
    // The message names the path to the nest, keys and element indices as the file has them.
    std::string nest = "{\"structures\": [1, {\"params\": ";
    for (int i = 0; i < 70; ++i) nest += "[";
    for (int i = 0; i < 70; ++i) nest += "]";
    EXPECT_EQ(error_of(nest + "}]}"),
              "f.json: structures[1].params[0][0][0][0][0]...: JSON nests deeper than 64 levels");
    // At the limit it parses.
    EXPECT_EQ(error_of(std::string(kMaxJsonDepth, '[') + std::string(kMaxJsonDepth, ']')), "");
    EXPECT_NE(error_of(std::string(kMaxJsonDepth + 1, '[') + std::string(kMaxJsonDepth + 1, ']')), "");
}

TEST(JsonInput, BadNumbersAndSyntaxNameTheFile) {
    EXPECT_EQ(error_of("{\"a\": 1e999}").rfind("f.json: not valid JSON", 0), 0u);
    EXPECT_EQ(error_of("{").rfind("f.json: not valid JSON", 0), 0u);
    EXPECT_EQ(error_of("\"\xff\"").rfind("f.json: not valid JSON", 0), 0u);  // not UTF-8
}

TEST(JsonInput, ExcerptsAreShortPrintableAndNeverThrow) {
    const nlohmann::json huge = std::string(5'000'000, 'x');
    const std::string e = json_excerpt(huge);
    EXPECT_LE(e.size(), 80u);
    EXPECT_EQ(e.substr(e.size() - 3), "...");
    nlohmann::json array = nlohmann::json::array();
    for (int i = 0; i < 100000; ++i) array.push_back(i);
    EXPECT_LE(json_excerpt(array).size(), 80u);
    EXPECT_EQ(json_excerpt(nlohmann::json("\xff\xfe")), "\"\xEF\xBF\xBD\xEF\xBF\xBD\"");  // replaced, no type_error
    EXPECT_EQ(json_excerpt(nlohmann::json(3)), "3");
}

}  // namespace
}  // namespace rcb
