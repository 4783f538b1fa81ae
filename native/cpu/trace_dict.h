// The pixel trace (trace.h) as the module returns it: numpy columns (gbviewer.render.trace reads them).
#pragma once

#include <nanobind/nanobind.h>

#include "trace.h"

namespace gbv {

nanobind::dict trace_dict(PixelTrace&& trace);

}  // namespace gbv
