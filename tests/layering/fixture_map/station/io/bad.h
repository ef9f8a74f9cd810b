#pragma once
// A fixture of check_folders.cmake: io/ is the bottom of station/, it may not include model/.
#include "station/model/car_model.h"
