// Vector patterns: paths in mm (pattern coordinates, y up), from HPGL/PLT, SVG and DXF files, with
// their outlines and the hatching of the areas their closed paths enclose (even-odd rule, so a
// hole inside a shape stays unmarked).
#pragma once

#include <map>
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
  // What the file holds and the pattern does not draw, by kind ("dimension", "image",
  // "polyface_mesh", "svg_image", ...; lower case, [a-z0-9_]): nothing is dropped silently,
  // each kind becomes a counted warning and a pattern_skipped_<kind> metric in the report.
  std::map<std::string, int> skipped;
  // What was read and drawn, by kind ("line", "arc", "insert", "text", "path", "use", ...),
  // for `insitu pattern inspect`.
  std::map<std::string, int> converted;
  int texts = 0;  // text items drawn (as glyph outlines or single strokes)
  // Whatever else the user should know: a font that was not found and the one used instead,
  // a construct read approximately. Each goes into the job report's warnings.
  std::vector<std::string> warnings;
  // The file's units as read ("mm", "in", "px (1/96 in)", ...), for `pattern inspect`.
  std::string units;

  // Appends `other`'s paths and adds its counts and warnings.
  void Append(VectorPattern other);
};

// HPGL / PLT (HP-GL/2 subset): IN, PU, PD, PA, PR with any number of coordinate pairs; 40
// plotter units per mm; other commands carry no geometry and are counted, not refused.
// Errors name the command and its position: parse_error for a non-number or an odd
// coordinate count; invalid_argument if nothing is drawn.
Result<VectorPattern> ParseHpgl(const std::string& text, const std::string& origin);
Result<VectorPattern> LoadHpgl(const std::string& path);

// SVG (the SVG 1.1 / Tiny subset design tools write): <path> (M L H V C S Q T A Z, absolute and
// relative; arcs with out-of-range radii scaled up as SVG says), <line>, <polyline>,
// <polygon>, <rect> (rx/ry: one given means both, each at most half the side), <circle>,
// <ellipse>, in <g>, <a>, nested <svg> and <switch> (its first child without
// requiredExtensions), with transform (matrix, translate, scale, rotate, skewX, skewY).
// <defs> and <symbol> are drawn only through <use> (href or xlink:href; x/y; a symbol's or
// svg's viewBox fitted into the use's width/height by preserveAspectRatio); a <use> that comes
// back to itself, nests deeper than 16 or names what the file lacks is skipped with a warning.
// Style from presentation attributes, CSS in <style> (type, class and id selectors, compounds,
// comma lists, descendant and child combinators; !important) and style="" in CSS's order
// (style attribute > CSS by specificity id > class > type > presentation attribute):
// fill none (or transparent) makes closed shapes open outlines, others are areas to hatch;
// display:none skips an element and its children, visibility:hidden and opacity 0 its own
// drawing; fill and stroke both none in so many words paints nothing. <text>/<tspan> are set by
// RenderText (font-family: the first family of the list fontconfig has; font-size as the em;
// x/y/dx/dy; text-anchor), their glyphs closed outlines. Images, gradient and pattern fills,
// clip paths, masks, filters, markers, foreignObject, textPath, animations and unknown
// elements are counted in `skipped` ("svg_image", "svg_gradient", ...; "svg_hidden" for what
// is hidden), `converted` counts what is drawn by element, `units` names the size's unit.
// Curves are flattened to within `tolerance_mm`. Units: the root's width/height (mm, cm, in,
// pt, pc, px = 1/96 in) over its viewBox, else 1 user unit = 1 px (with a warning);
// y is flipped so the pattern's y points up. Errors name the element and attribute:
// parse_error for XML, path data, lengths and transforms; invalid_argument if nothing is drawn,
// or for a file past the limits (256 MB, 10^6 elements with <use> expanded, 5 10^6 points).
Result<VectorPattern> ParseSvg(const std::string& text, const std::string& origin,
                               double tolerance_mm = 0.005);
Result<VectorPattern> LoadSvg(const std::string& path, double tolerance_mm = 0.005);

// DXF (ASCII, R12 to R2018): the model space's LINE, ARC, CIRCLE, ELLIPSE, LWPOLYLINE and
// POLYLINE (with bulges; 3D polylines projected), SPLINE (control points, knots, weights),
// SOLID/TRACE, HATCH boundary loops (closed, to be hatched by the job; the file's pattern lines
// are not drawn), TEXT, MTEXT and ATTRIB (through RenderText: the style's TrueType family, or a
// Hershey font for SHX fonts), INSERT block references (nested, scaled, mirrored, rotated,
// arrayed) and DIMENSIONs from their blocks; entities with an extrusion direction are placed by
// the AutoCAD arbitrary axis algorithm and projected on XY. Open curves whose ends meet (within
// 0.001 mm or 1e-6 of the drawing) are joined into closed loops. Units from $INSUNITS (mm if
// absent). Closed paths are areas. What is drawn is counted in `converted`, what is not
// (meshes, 3D solids, images, points, leaders, paper space, a missing block, ...) in `skipped`,
// empty texts and attribute templates in ignored_commands, text that cannot be rendered in
// skipped and `warnings`. Reading stops at the first EOF; a missing EOF is accepted after a
// complete ENTITIES section. Errors name the line: parse_error for malformed groups, a binary
// DXF, a file cut inside ENTITIES or a block that inserts itself; out_of_range for a drawing
// that expands beyond the reader's limits (32 nested blocks, 100000 copies in one INSERT array,
// 1 million entities, 5 million points); invalid_argument if nothing is drawn.
Result<VectorPattern> ParseDxf(const std::string& text, const std::string& origin,
                               double tolerance_mm = 0.005);
Result<VectorPattern> LoadDxf(const std::string& path, double tolerance_mm = 0.005);

// A vector drawing by its extension: .svg, .dxf, .plt/.hpgl/.hpg/.hgl. Errors: the reader's, or
// invalid_argument for another extension.
Result<VectorPattern> LoadVectorFile(const std::string& path, double tolerance_mm = 0.005);

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
