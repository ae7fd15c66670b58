// Colour frames reduced to the one plane the finders read. A colour camera sees the pointer's
// red line mostly through its red filters (a 650 nm diode passes the red filter at ~0.9 of its
// peak, the green at ~0.1, the blue at ~0.05 on common CMOS mosaics), while white room light
// and a white label pass all three: the laser's own channel holds the most stripe for the
// least background.
//
// In: an ImageView whose format is a Bayer mosaic, RGB or BGR (8- or 10..16-bit samples), or
// mono (copied as it is). Out: a mono Image of the same size and depth whose pixel (u, v) is
// the chosen channel at pixel (u, v): the mosaic's own sample where its filter is that colour,
// else the mean of its nearest samples of that colour (bilinear demosaicking of one channel),
// so a centre found in it lies in the sensor's own pixel coordinates.
#pragma once

#include "insitu/core/status.h"
#include "insitu/vision/image.h"

namespace insitu::vision {

enum class ColourChannel { kRed, kGreen, kBlue };

// The filter a laser line of this wavelength passes best: red from 590 nm (a pointer's 635-690
// nm, an IR source's visible aiming diode), green from 490 nm (520 and 532 nm lines), blue
// below (405-450 nm lines). Errors: invalid_argument outside 350..1100 nm, where no colour
// camera's filters separate anything.
Result<ColourChannel> ChannelOfWavelength(double wavelength_nm);

// Errors: invalid_argument for an empty or malformed view (a stride under a row, a bit depth
// other than 8 or 10..16).
Status ReduceToChannel(const ImageView& image, ColourChannel channel, Image* out);

}  // namespace insitu::vision
