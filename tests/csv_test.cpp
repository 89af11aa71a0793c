// CSV import of boxes and rays: optional header, comments, CRLF; errors with file and line.
#include <gtest/gtest.h>

#include "core/scene/import/csv.h"
#include "core/base/error.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

std::string boxes_error(const std::string& text) {
    return test::input_error_of([&] { parse_boxes_csv(text, "boxes.csv"); });
}

TEST(Csv, ReadsBoxesWithOrWithoutHeaderCommentsAndCrlf) {
    const auto a =
        parse_boxes_csv("uid,minx,miny,minz,maxx,maxy,maxz\n1,0,0,0,1,1,1\n2, -1.5, 2, 3e2, 0, 2.5, 400\n", "a");
    const auto b = parse_boxes_csv("# exported\r\n1,0,0,0,1,1,1\r\n\r\n2,-1.5,2,300,0,2.5,400\r\n", "b");
    ASSERT_EQ(a.size(), 2u);
    EXPECT_EQ(a, b);
    EXPECT_EQ(a[1].uid, 2u);
    EXPECT_EQ(a[1].box.min.z, 300.0f);
    EXPECT_TRUE(parse_boxes_csv("", "empty").empty());
}

TEST(Csv, BoxErrorsNameFileLineAndField) {
    EXPECT_EQ(boxes_error("1,0,0,0,1,1\n"),
              "boxes.csv:1: expected 7 fields (uid,minx,miny,minz,maxx,maxy,maxz), got 6");
    EXPECT_EQ(boxes_error("1,0,0,0,1,1,1\n2,0,abc,0,1,1,1\n"), "boxes.csv:2: field 3 (miny): 'abc' is not a number");
    EXPECT_EQ(boxes_error("1,0,0,0,1,1,1\n-4,0,0,0,1,1,1\n"),
              "boxes.csv:2: field 1 (uid): '-4' is not an integer in 0..4294967295");
    EXPECT_EQ(boxes_error("1,0,0,0,1,1,1\n2,0,0,nan,1,1,1\n"), "boxes.csv:2: uid 2: non-finite coordinate");
    EXPECT_EQ(boxes_error("7,0,0,0,1,-1,1\n"), "boxes.csv:1: uid 7: min > max on axis y");
    EXPECT_EQ(boxes_error("# c\n5,0,0,0,1,1,1\n\n5,0,0,0,1,1,1\n"), "boxes.csv:4: duplicate uid 5 (first on line 2)");
    EXPECT_EQ(boxes_error("uid,minx,miny\n"),
              "boxes.csv:1: header has 3 columns, expected 7 (uid,minx,miny,minz,maxx,maxy,maxz)");
}

TEST(Csv, ReadsRaysAndRejectsBadOnes) {
    const auto rays = parse_rays_csv("x0,y0,z0,x1,y1,z1\n0,0,0,1,2,3\n", "rays.csv");
    ASSERT_EQ(rays.size(), 1u);
    EXPECT_EQ(rays[0].p1.y, 2.0f);
    EXPECT_EQ(test::input_error_of([] { parse_rays_csv("0,0,0,1,2,3\n0,0,inf,1,2,3\n", "rays.csv"); }),
              "rays.csv:2: non-finite coordinate");
    EXPECT_THROW(read_rays_csv("/nonexistent/rays.csv"), InputError);
}

TEST(Csv, AByteOrderMarkIsNotPartOfTheFirstRow) {
    // Spreadsheets write a UTF-8 BOM; without a header, the first row used to be taken for one.
    const auto plain = parse_boxes_csv("1,0,0,0,1,1,1\n2,0,0,0,2,2,2\n", "a");
    EXPECT_EQ(parse_boxes_csv("\xEF\xBB\xBF"
                              "1,0,0,0,1,1,1\n2,0,0,0,2,2,2\n",
                              "bom.csv"),
              plain);
    EXPECT_EQ(
        parse_boxes_csv("\xEF\xBB\xBFuid,minx,miny,minz,maxx,maxy,maxz\r\n1,0,0,0,1,1,1\r\n2,0,0,0,2,2,2\r\n", "b"),
        plain);
    EXPECT_EQ(parse_rays_csv("\xEF\xBB\xBF"
                             "0,0,0,1,2,3\n",
                             "rays.csv")
                  .size(),
              1u);
}

TEST(Csv, CoordinatesBeyondTheLimitAreRejectedNamingLineUidAndLimit) {
    // One box 1e20 long among unit boxes aborted Embree; beyond float's range read as "not a number".
    std::string text = "uid,minx,miny,minz,maxx,maxy,maxz\n";
    for (int i = 0; i < 200; ++i) text += std::to_string(i) + ",0,0,0,1,1,1\n";
    EXPECT_EQ(boxes_error(text + "200,0,40,0,1e20,41,1\n"),
              "boxes.csv:202: uid 200: field 5 (maxx): coordinate '1e20' beyond ±1e+15 (the largest magnitude every "
              "structure handles exactly)");
    EXPECT_NE(
        boxes_error("7,-3e38,0,0,1,1,1\n").find("boxes.csv:1: uid 7: field 2 (minx): coordinate '-3e38' beyond ±1e+15"),
        std::string::npos);
    EXPECT_NE(
        boxes_error("7,0,0,0,1,1,1e39\n").find("boxes.csv:1: uid 7: field 7 (maxz): coordinate '1e39' beyond ±1e+15"),
        std::string::npos);
    EXPECT_NE(boxes_error("7,0,0,0,1,1,1e400\n").find("field 7 (maxz): coordinate '1e400' beyond ±1e+15"),
              std::string::npos);
    // Nonzero coordinates smaller than 1e-20, down to beyond double's range, are refused too.
    EXPECT_EQ(boxes_error("7,0,0,3e-25,1,1,1\n"),
              "boxes.csv:1: uid 7: field 4 (minz): coordinate '3e-25' below 1e-20 in magnitude (write 0: float "
              "arithmetic is not exact that small)");
    EXPECT_NE(boxes_error("7,0,0,-1e-40,1,1,1\n").find("field 4 (minz): coordinate '-1e-40' below 1e-20"),
              std::string::npos);
    EXPECT_NE(boxes_error("7,0,0,1e-400,1,1,1\n").find("field 4 (minz): coordinate '1e-400' below 1e-20"),
              std::string::npos);
    // At the limits, and zero, are fine.
    const auto edge = parse_boxes_csv("7,-1e15,-0,1e-20,1e15,0,1\n", "edge.csv");
    ASSERT_EQ(edge.size(), 1u);
    EXPECT_EQ(edge[0].box.min.x, -1e15f);
    EXPECT_EQ(edge[0].box.min.z, 1e-20f);
    EXPECT_EQ(test::input_error_of([] { parse_rays_csv("0,0,0,1,2,3\n0,0,0,1,2.5e15,3\n", "rays.csv"); }),
              "rays.csv:2: field 5 (y1): coordinate '2.5e15' beyond ±1e+15 (the largest magnitude every "
              "structure handles exactly)");
}

TEST(Csv, ErrorsQuoteAtMostAnExcerptOfTheField) {
    const std::string huge(10'000'000, '7');
    const std::string e = boxes_error("1,0,0,0,1,1,1\n2,0,x" + huge + ",0,1,1,1\n");
    EXPECT_LT(e.size(), 200u);
    EXPECT_EQ(e, "boxes.csv:2: field 3 (miny): 'x" + std::string(79, '7') + "'… is not a number");
    EXPECT_EQ(boxes_error("1,0,0,0,1,1,1\n-4\x1b[2J,0,0,0,1,1,1\n"),
              "boxes.csv:2: field 1 (uid): '-4\\x1B[2J' is not an integer in 0..4294967295");
}

TEST(QuotedExcerpt, QuotesEscapesAndCutsUserText) {
    EXPECT_EQ(quoted_excerpt("abc"), "'abc'");
    EXPECT_EQ(quoted_excerpt(""), "''");
    // A BOM, a tab and a newline are shown, not sent to the terminal.
    EXPECT_EQ(quoted_excerpt("\xEF\xBB\xBF"
                             "a\tb\n"),
              "'\\xEF\\xBB\\xBFa\\x09b\\x0A'");
    EXPECT_EQ(quoted_excerpt(std::string(80, 'x')), "'" + std::string(80, 'x') + "'");
    EXPECT_EQ(quoted_excerpt(std::string(10'000'000, 'x')), "'" + std::string(80, 'x') + "'…");
    EXPECT_EQ(quoted_excerpt("abcdef", 4), "'abcd'…");
    // An escape that does not fit is left out whole.
    EXPECT_EQ(quoted_excerpt("ab\x01", 4), "'ab'…");
}

}  // namespace
}  // namespace rcb
