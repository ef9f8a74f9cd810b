#pragma once
// The subcommands of `linecal`. Each takes the arguments after its own name and returns the
// process exit code (cli::ExitCode). The table in main.cc maps names to these functions.

#include <string>
#include <vector>

namespace linecal::tools {

using Args = std::vector<std::string>;

int RunBoards(const Args& args);          // cmd_boards.cc
int RunPattern(const Args& args);         // cmd_pattern.cc
int RunCaptureCheck(const Args& args);    // cmd_capture.cc
int RunSim(const Args& args);             // cmd_sim.cc
int RunLidarTopview(const Args& args);    // cmd_topview.cc
int RunLidarDecode(const Args& args);     // cmd_lidar.cc
int RunRadarDecode(const Args& args);     // cmd_radar.cc
int RunRadarCalibrate(const Args& args);  // cmd_radar_cal.cc
int RunEvalRadar(const Args& args);       // cmd_eval_radar.cc
int RunEvalLidar(const Args& args);       // cmd_eval_lidar.cc
int RunDetect(const Args& args);          // cmd_detect.cc
int RunCalibrate(const Args& args);       // cmd_calibrate.cc
int RunEvalCalibrate(const Args& args);   // cmd_eval_calibrate.cc
int RunEvalStation(const Args& args);     // cmd_eval_station.cc
int RunCycleStart(const Args& args);      // cmd_cycle.cc
int RunCycleShow(const Args& args);       // cmd_cycle.cc
int RunCyclesList(const Args& args);      // cmd_cycle.cc
int RunStatus(const Args& args);          // cmd_cycle.cc
int RunAftersale(const Args& args);       // cmd_aftersale.cc
int RunSimLanes(const Args& args);        // cmd_sim_lanes.cc
int RunEvalAftersale(const Args& args);   // cmd_eval_aftersale.cc
int RunPlan(const Args& args);            // cmd_plan.cc
int RunPlanCheck(const Args& args);       // cmd_plan.cc
int RunServeSensors(const Args& args);    // cmd_serve_sensors.cc
int RunPlantMigrate(const Args& args);    // cmd_plant.cc
int RunPlantCycles(const Args& args);     // cmd_plant.cc
int RunPlantYield(const Args& args);      // cmd_plant.cc
int RunPlantExport(const Args& args);     // cmd_plant.cc

}  // namespace linecal::tools
