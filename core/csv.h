#pragma once
/// CSV input: static scenes (`uid,minx,miny,minz,maxx,maxy,maxz`) and rays (`x0,y0,z0,x1,y1,z1`).
/// A header line is optional; blank lines and lines starting with '#' are skipped. Errors name the
/// file and line: "boxes.csv:12: field 4 (minz): 'abc' is not a number".

#include <string>
#include <vector>

#include "core/scene.h"

namespace rcb {

std::vector<Object> read_boxes_csv(const std::string& path);
std::vector<Segment> read_rays_csv(const std::string& path);

/// The same, from text already in memory (`name` is used in messages).
std::vector<Object> parse_boxes_csv(const std::string& text, const std::string& name);
std::vector<Segment> parse_rays_csv(const std::string& text, const std::string& name);

}  // namespace rcb
