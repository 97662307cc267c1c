#pragma once

#include <string>

#include "hal/pixel_conversion.hpp"

struct _GError;

// Shared by the two halves of AravisCamera (aravis_camera.cpp streams, aravis_genicam.cpp speaks
// GenICam); no other user.
namespace laserline::hal {

// Takes the message out of a GError (and frees it); "" when there was none.
std::string take_gerror(_GError*& error);
// The index of a pixel format in the backend's table (aravis_pixel_formats()), -1 for none.
int aravis_pixel_format_index(const std::string& name);
// Its layout; `index` from aravis_pixel_format_index(), not -1.
const SourceFormat& aravis_source_format(int index);

}  // namespace laserline::hal
