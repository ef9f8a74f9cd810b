// A fixture of check_folders.cmake: calibrate is not a simulating command.
#include "station/sim/simulator.h"
