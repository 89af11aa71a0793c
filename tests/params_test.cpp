// Typed parameters: JSON in and out, and validation messages with the JSON path.
#include <gtest/gtest.h>

#include "accel/bvh/dynamic_bvh.h"
#include "accel/bvh/wide_bvh.h"
#include "accel/interface/params.h"
#include "accel/registry.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

constexpr FieldOptions kQualityOptions{.tunable = false, .choices = "low,medium", .recorded_when_default = false};

struct ExampleParams {
    double density = 2.0;
    int max_depth = 4;
    bool rotate = true;
    std::string quality = "low";
    static constexpr auto fields() {
        return std::tuple{Field{"density", &ExampleParams::density, 0.01, 64.0, "objects per cell", kLogScale},
                          Field{"max_depth", &ExampleParams::max_depth, 1, 16, "levels"},
                          Field{"rotate", &ExampleParams::rotate, 0, 1, "tree rotations", kNotTuned},
                          Field{"quality", &ExampleParams::quality, 0, 0, "build quality", kQualityOptions}};
    }
};

std::string error_of(const nlohmann::json& j) {
    return test::input_error_of([&] { params_from_json<ExampleParams>(j, "structures[2].params", "example"); });
}

TEST(Params, DefaultsOverriddenByJsonAndBack) {
    const ExampleParams p = params_from_json<ExampleParams>({{"max_depth", 7}, {"quality", "medium"}}, "p", "example");
    EXPECT_EQ(p.max_depth, 7);
    EXPECT_EQ(p.density, 2.0);
    EXPECT_EQ(p.quality, "medium");
    EXPECT_EQ(params_to_json(p),
              (nlohmann::json{{"density", 2.0}, {"max_depth", 7}, {"rotate", true}, {"quality", "medium"}}));
}

TEST(Params, ValidationMessagesNameThePathAndTheExpectation) {
    EXPECT_EQ(error_of({{"max_depth", "x"}}),
              "structures[2].params.max_depth: expected an integer in 1..16, got \"x\"");
    EXPECT_EQ(error_of({{"max_depth", 17}}), "structures[2].params.max_depth: expected an integer in 1..16, got 17");
    EXPECT_EQ(error_of({{"max_depth", 2.5}}), "structures[2].params.max_depth: expected an integer in 1..16, got 2.5");
    EXPECT_EQ(error_of({{"density", 0}}), "structures[2].params.density: expected a number in 0.01..64, got 0");
    EXPECT_EQ(error_of({{"rotate", 1}}), "structures[2].params.rotate: expected true or false, got 1");
    EXPECT_EQ(error_of({{"quality", "high"}}),
              "structures[2].params.quality: expected one of low, medium, got \"high\"");
    EXPECT_EQ(
        error_of({{"max_deph", 3}}),
        "structures[2].params.max_deph: unknown parameter of example (known: density, max_depth, rotate, quality)");
    EXPECT_EQ(error_of(nlohmann::json::array()), "structures[2].params: expected an object of parameters, got []");
}

TEST(Params, SpecsDescribeTypesRangesAndDefaults) {
    const auto specs = param_specs<ExampleParams>();
    ASSERT_EQ(specs.size(), 4u);
    EXPECT_EQ(specs[0].kind, ParamKind::real);
    EXPECT_TRUE(specs[0].log_scale);
    EXPECT_EQ(specs[1].kind, ParamKind::integer);
    EXPECT_EQ(specs[1].default_value, 4);
    EXPECT_EQ(specs[2].kind, ParamKind::boolean);
    EXPECT_FALSE(specs[2].tunable);
    EXPECT_EQ(specs[3].choices, (std::vector<std::string>{"low", "medium"}));
    EXPECT_FALSE(specs[3].tunable);
    EXPECT_FALSE(specs[3].recorded_when_default);
    EXPECT_TRUE(specs[1].recorded_when_default);
}

enum class Quality { low, medium };

TEST(Params, ChoicesParseOnceIntoTheirEnum) {
    EXPECT_EQ(parse_choice<Quality>("low,medium", "low", "example quality"), Quality::low);
    EXPECT_EQ(parse_choice<Quality>("low,medium", "medium", "example quality"), Quality::medium);
    try {
        parse_choice<Quality>("low,medium", "high", "example quality");
        FAIL();
    } catch (const InputError& e) {
        EXPECT_STREQ(e.what(), "example quality: expected one of low, medium, got \"high\"");
    }
}

TEST(Params, StructuresRefuseAChoiceOutsideTheirList) {
    // Params made in C++ skip the JSON check; the constructor's parse still refuses the text.
    WideBvh::Params w;
    w.push = "sideways";
    EXPECT_THROW(WideBvh{w}, InputError);
    DynamicBvh::Params d;
    d.mode = "sideways";
    EXPECT_THROW(DynamicBvh{d}, InputError);
}

TEST(Params, CommandLineKeyValues) {
    EXPECT_EQ(parse_key_value("density=2.5").second, 2.5);
    EXPECT_EQ(parse_key_value("max_depth=3").second, 3);
    EXPECT_EQ(parse_key_value("rotate=false").second, false);
    EXPECT_EQ(parse_key_value("quality=medium").second, "medium");
    EXPECT_THROW(parse_key_value("density"), InputError);
}

}  // namespace
}  // namespace rcb
