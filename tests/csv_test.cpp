// CSV import of boxes and rays: optional header, comments, CRLF; errors with file and line.
#include <gtest/gtest.h>

#include "core/csv.h"
#include "core/error.h"

namespace rcb {
namespace {

std::string boxes_error(const std::string& text) {
    try {
        parse_boxes_csv(text, "boxes.csv");
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

TEST(Csv, ReadsBoxesWithOrWithoutHeaderCommentsAndCrlf) {
    const auto a = parse_boxes_csv("uid,minx,miny,minz,maxx,maxy,maxz\n1,0,0,0,1,1,1\n2, -1.5, 2, 3e2, 0, 2.5, 400\n", "a");
    const auto b = parse_boxes_csv("# exported\r\n1,0,0,0,1,1,1\r\n\r\n2,-1.5,2,300,0,2.5,400\r\n", "b");
    ASSERT_EQ(a.size(), 2u);
    EXPECT_EQ(a, b);
    EXPECT_EQ(a[1].uid, 2u);
    EXPECT_EQ(a[1].box.min.z, 300.0f);
    EXPECT_TRUE(parse_boxes_csv("", "empty").empty());
}

TEST(Csv, BoxErrorsNameFileLineAndField) {
    EXPECT_EQ(boxes_error("1,0,0,0,1,1\n"), "boxes.csv:1: expected 7 fields (uid,minx,miny,minz,maxx,maxy,maxz), got 6");
    EXPECT_EQ(boxes_error("1,0,0,0,1,1,1\n2,0,abc,0,1,1,1\n"), "boxes.csv:2: field 3 (miny): 'abc' is not a number");
    EXPECT_EQ(boxes_error("1,0,0,0,1,1,1\n-4,0,0,0,1,1,1\n"), "boxes.csv:2: field 1 (uid): '-4' is not an integer in 0..4294967295");
    EXPECT_EQ(boxes_error("1,0,0,0,1,1,1\n2,0,0,nan,1,1,1\n"), "boxes.csv:2: uid 2: non-finite coordinate");
    EXPECT_EQ(boxes_error("7,0,0,0,1,-1,1\n"), "boxes.csv:1: uid 7: min > max on axis y");
    EXPECT_EQ(boxes_error("# c\n5,0,0,0,1,1,1\n\n5,0,0,0,1,1,1\n"), "boxes.csv:4: duplicate uid 5 (first on line 2)");
    EXPECT_EQ(boxes_error("uid,minx,miny\n"), "boxes.csv:1: header has 3 columns, expected 7 (uid,minx,miny,minz,maxx,maxy,maxz)");
}

TEST(Csv, ReadsRaysAndRejectsBadOnes) {
    const auto rays = parse_rays_csv("x0,y0,z0,x1,y1,z1\n0,0,0,1,2,3\n", "rays.csv");
    ASSERT_EQ(rays.size(), 1u);
    EXPECT_EQ(rays[0].p1.y, 2.0f);
    try {
        parse_rays_csv("0,0,0,1,2,3\n0,0,inf,1,2,3\n", "rays.csv");
        FAIL();
    } catch (const InputError& e) {
        EXPECT_STREQ(e.what(), "rays.csv:2: non-finite coordinate");
    }
    EXPECT_THROW(read_rays_csv("/nonexistent/rays.csv"), InputError);
}

TEST(QuotedExcerpt, QuotesEscapesAndCutsUserText) {
    EXPECT_EQ(quoted_excerpt("abc"), "'abc'");
    EXPECT_EQ(quoted_excerpt(""), "''");
    // A BOM, a tab and a newline are shown, not sent to the terminal.
    EXPECT_EQ(quoted_excerpt("\xEF\xBB\xBF" "a\tb\n"), "'\\xEF\\xBB\\xBFa\\x09b\\x0A'");
    EXPECT_EQ(quoted_excerpt(std::string(80, 'x')), "'" + std::string(80, 'x') + "'");
    EXPECT_EQ(quoted_excerpt(std::string(10'000'000, 'x')), "'" + std::string(80, 'x') + "'…");
    EXPECT_EQ(quoted_excerpt("abcdef", 4), "'abcd'…");
    // An escape that does not fit is left out whole.
    EXPECT_EQ(quoted_excerpt("ab\x01", 4), "'ab'…");
}

}  // namespace
}  // namespace rcb
