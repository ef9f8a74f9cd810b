// A fixture of check_folders.cmake: drivers do real I/O, below the daemon core.
#include "daemon/core/station_core.h"
