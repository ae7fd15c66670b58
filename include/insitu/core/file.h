// Writing a file so that a reader never sees half of it: the text goes to `path`.tmp, which
// then replaces `path` by rename (atomic on one file system).
#pragma once

#include <string>

#include "insitu/core/status.h"

namespace insitu {

// Errors: device_error naming the file (cannot write the temporary, cannot replace `path`);
// the temporary is removed on failure.
Status WriteFileAtomically(const std::string& path, const std::string& text);

}  // namespace insitu
