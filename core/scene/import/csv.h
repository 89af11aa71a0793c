#pragma once
/// CSV input: static scenes (`uid,minx,miny,minz,maxx,maxy,maxz`) and rays (`x0,y0,z0,x1,y1,z1`).
/// A header line is optional; blank lines and lines starting with '#' are skipped, and so is a
/// leading UTF-8 byte-order mark. Coordinates must lie within ±kMaxCoordinate (recording_io.h).
/// Errors name the file and line, and quote at most an excerpt of the field (quoted_excerpt):
/// "boxes.csv:12: field 4 (minz): 'abc' is not a number".

#include <string>
#include <vector>

#include "core/scene/scene.h"

namespace rcb {

std::vector<Object> read_boxes_csv(const std::string& path);
std::vector<Segment> read_rays_csv(const std::string& path);

/// The same, from text already in memory (`name` is used in messages).
std::vector<Object> parse_boxes_csv(const std::string& text, const std::string& name);
std::vector<Segment> parse_rays_csv(const std::string& text, const std::string& name);

}  // namespace rcb
