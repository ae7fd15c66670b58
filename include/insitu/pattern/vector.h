// Vector patterns: paths in mm (pattern coordinates, y up), from HPGL/PLT, SVG and DXF files, with
// their outlines and the hatching of the areas their closed paths enclose (even-odd rule, so a
// hole inside a shape stays unmarked).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "insitu/core/status.h"
#include "insitu/pattern/raster.h"

namespace insitu::pattern {

struct Polyline {
  std::vector<Eigen::Vector2d> points;
  bool closed = false;  // last point joins the first
};

struct VectorPattern {
  std::vector<Polyline> paths;
  int ignored_commands = 0;  // file commands with no geometry (pen select, speed, ...)
};

// HPGL / PLT (HP-GL/2 subset): IN, PU, PD, PA, PR with any number of coordinate pairs; 40
// plotter units per mm; other commands carry no geometry and are counted, not refused.
// Errors name the command and its position: parse_error for a non-number or an odd
// coordinate count; invalid_argument if nothing is drawn.
Result<VectorPattern> ParseHpgl(const std::string& text, const std::string& origin);
Result<VectorPattern> LoadHpgl(const std::string& path);

// SVG: <path> (M L H V C S Q T A Z, absolute and relative), <line>, <polyline>, <polygon>,
// <rect>, <circle>, <ellipse>, inside nested <g> with transform (matrix, translate, scale,
// rotate, skewX, skewY). Curves and arcs are flattened to within `tolerance_mm`. Units: the
// root's width/height (mm, cm, in, pt, px = 1/96 in) over its viewBox, else 1 user unit = 1 px;
// y is flipped so the pattern's y points up. Elements with fill="none" are open outlines;
// other closed shapes can be hatched. Errors name the element and attribute: parse_error for
// XML or path-data errors; invalid_argument if nothing is drawn.
Result<VectorPattern> ParseSvg(const std::string& text, const std::string& origin,
                               double tolerance_mm = 0.005);
Result<VectorPattern> LoadSvg(const std::string& path, double tolerance_mm = 0.005);

// DXF (ASCII): LINE, LWPOLYLINE and POLYLINE (with bulges), ARC, CIRCLE, ELLIPSE, SPLINE
// (control points and knots) from the ENTITIES section; units from $INSUNITS (mm if absent);
// closed polylines, circles and full ellipses are areas. Blocks are not expanded; other
// entities (text, dimensions) are counted in ignored_commands. Errors name the line.
Result<VectorPattern> ParseDxf(const std::string& text, const std::string& origin,
                               double tolerance_mm = 0.005);
Result<VectorPattern> LoadDxf(const std::string& path, double tolerance_mm = 0.005);

// Travel order of the outlines: the paths reordered greedily, each next the one whose entry is
// nearest to where the last ended (from `start_mm`), open paths reversed when their far end is
// nearer and closed paths rotated to start at their nearest vertex. Returns the total jump
// length (mm) of the new order; *before, if given, gets that of the file's order.
double OrderForTravel(VectorPattern* pattern, const Eigen::Vector2d& start_mm,
                      double* before = nullptr);

// Every path as segments (the outlines to mark).
std::vector<Segment2> Outline(const VectorPattern& pattern);

// Hatch lines at `angle_deg`, `spacing_mm` apart (one through the origin), inside the closed
// paths by the even-odd rule. Alternate lines run in opposite directions. Errors:
// invalid_argument for a non-positive spacing or no closed path.
Result<std::vector<Segment2>> HatchPolygons(const VectorPattern& pattern, double spacing_mm,
                                            double angle_deg);

}  // namespace insitu::pattern
