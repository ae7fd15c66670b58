// Text as marking geometry: glyph outlines from outline fonts (TrueType/OpenType/Type 1 through
// FreeType, the family found by fontconfig) to be filled by hatching, or single strokes from
// Hershey fonts (the engraving convention: each stroke marked once, nothing to hatch).
// Coordinates are pattern mm, y up, the first line's baseline starting at the origin.
#pragma once

#include <string>

#include "insitu/core/status.h"
#include "insitu/pattern/vector.h"

namespace insitu::pattern {

enum class TextAlign { kLeft, kCenter, kRight };

struct TextStyle {
  // A fontconfig pattern ("DejaVu Sans", "Liberation Serif:bold", "monospace") for outline
  // glyphs, or "hershey:NAME" for a Hershey single-stroke font (hershey:rowmans, futural,
  // scripts, ...: the names of Debian's hershey-fonts-data, read from /usr/share/hershey-fonts
  // or $HERSHEY_FONTS_DIR; ASCII only). A family fontconfig does not have is replaced by its
  // closest match, named in the result's warnings.
  std::string font = "DejaVu Sans";
  // The size: the height of a capital letter (cap height, as DXF TEXT and engraving software
  // give it: the font's OS/2 sCapHeight, else the height of its 'H'), or with `size_is_em` the
  // em size (CSS/SVG font-size; 32 grid units for a Hershey font).
  double height_mm = 5.0;
  bool size_is_em = false;
  double letter_spacing_mm = 0.0;  // added between glyphs, after kerning (may be negative)
  double line_spacing = 1.2;       // baseline to baseline, in multiples of the em size
  TextAlign align = TextAlign::kLeft;
  // 0: along the baseline (+x). Otherwise the baseline is bent onto a circle of this radius
  // (mm) about (0, -radius) (text on the outside, reading clockwise); negative: on the inside
  // about (0, |radius|), reading counter-clockwise. Glyph shapes follow the arc: x along the
  // line becomes arc length on the baseline circle, height above the baseline distance from it.
  // |radius| must exceed height_mm; text that would reach the centre is refused.
  double arc_radius_mm = 0.0;

  // invalid_argument naming the field: a non-finite or non-positive height_mm or line_spacing,
  // a non-finite letter_spacing_mm or arc_radius_mm, a nonzero arc_radius_mm not larger in size
  // than height_mm, an empty font or a "hershey:" name other than letters, digits, '_', '-'.
  Status Validate() const;
};

// `utf8` laid out from the origin: the first line's baseline on y = 0 (y up), lines split at
// '\n' (or "\r\n") going down, each aligned about x = 0 as `align` says (by its advance width).
// Outline fonts give closed paths (holes by the even-odd rule, as VectorPattern hatching
// expects) flattened to within `tolerance_mm`; Hershey fonts give open strokes. One glyph per
// code point, left to right, with the font's pair kerning; no ligatures or complex-script
// shaping. Invalid UTF-8 is drawn as U+FFFD, with a warning. A character the font has no glyph
// for is left out (no advance), counted in `skipped["missing_glyph"]` and named in a warning.
// The result's `texts` is 1, `converted["glyph"]` the glyphs drawn (spaces draw nothing), and
// `units` "mm". Errors: invalid_argument (style, tolerance, empty text, an arc too small for
// the lines below the first), not_found (no font at all: fontconfig finds none, or the Hershey
// font's file is missing; the message lists the installed ones), parse_error (a damaged
// Hershey font file), out_of_range (a text of more than 2 million outline points). Curves are
// flattened no finer than 1e-4 em, whatever `tolerance_mm` asks.
Result<VectorPattern> RenderText(const std::string& utf8, const TextStyle& style,
                                 double tolerance_mm = 0.005);

}  // namespace insitu::pattern
