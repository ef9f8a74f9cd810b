// linecal: the command line of the calibration station. `linecal help` lists subcommands.
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace {

struct Subcommand {
  std::vector<std::string> words;  // e.g. {"lidar", "decode"}
  const char* summary;
  int (*run)(const linecal::tools::Args&);
};

const std::vector<Subcommand>& Subcommands() {
  using namespace linecal::tools;
  static const std::vector<Subcommand> kTable = {
      {{"boards"}, "list the calibration boards (--json)", RunBoards},
      {{"pattern"}, "write a printable board pattern (SVG/PNG)", RunPattern},
      {{"capture", "check"}, "validate a capture directory", RunCaptureCheck},
      {{"sim"}, "simulate a car in a station and write a capture", RunSim},
      {{"sim", "lanes"},
       "render a lane scene for the after-sale tool (PNG + its input JSON)",
       RunSimLanes},
      {{"lidar", "topview"}, "draw LiDAR scans seen from above (PNG)", RunLidarTopview},
      {{"lidar", "decode"},
       "decode LiDAR packets (pcap) into one PCD per rotation",
       RunLidarDecode},
      {{"radar", "decode"}, "decode a radar CAN log (candump) into detections", RunRadarDecode},
      {{"radar", "calibrate"},
       "radar mounting yaw from a capture's corner reflectors",
       RunRadarCalibrate},
      {{"eval", "radar"}, "Monte Carlo evaluation of radar yaw calibration", RunEvalRadar},
      {{"eval", "lidar"}, "Monte Carlo evaluation of LiDAR-to-car calibration", RunEvalLidar},
      {{"eval", "calibrate"},
       "Monte Carlo evaluation of camera-to-car calibration",
       RunEvalCalibrate},
      {{"eval", "station"},
       "full-physics Monte Carlo evaluation of the whole car (detectors in the loop)",
       RunEvalStation},
      {{"eval", "aftersale"},
       "Monte Carlo evaluation of the after-sale lane calibration",
       RunEvalAftersale},
      {{"detect"}, "find a calibration board in an image (--json, --overlay)", RunDetect},
      {{"calibrate"}, "compute a calibration cycle from a capture (--json)", RunCalibrate},
      {{"cycle", "start"},
       "start a cycle on the daemon (--wait: follow it and print the results)",
       RunCycleStart},
      {{"cycle", "show"}, "show a stored cycle", RunCycleShow},
      {{"cycles", "list"}, "list stored cycles (--vin, --verdict)", RunCyclesList},
      {{"status"}, "the daemon's station status", RunStatus},
      {{"aftersale"},
       "camera calibration from lane lines in one image (--json, --out, --export)",
       RunAftersale},
      {{"plan"}, "plan board and reflector placement for a car model in a station", RunPlan},
      {{"plan", "check"},
       "can every sensor be calibrated with this layout? (reasons when not)",
       RunPlanCheck},
      {{"plant", "migrate"},
       "create or upgrade the plant PostgreSQL schema and roles",
       RunPlantMigrate},
      {{"plant", "cycles"},
       "every attempt on a VIN at every station (plant database)",
       RunPlantCycles},
      {{"plant", "yield"},
       "first-pass yield and top failure reasons (plant database)",
       RunPlantYield},
      {{"plant", "export"}, "cycles since a date as CSV or JSON (plant database)", RunPlantExport},
      {{"serve-sensors"},
       "serve a capture as live sensors (fake GigE cameras, UDP LiDAR, candump radar)",
       RunServeSensors},
  };
  return kTable;
}

void PrintHelp(std::FILE* out) {
  std::fprintf(out,
               "usage: linecal SUBCOMMAND [options]   (linecal SUBCOMMAND --help for details)\n\n"
               "subcommands:\n");
  for (const Subcommand& s : Subcommands()) {
    std::string name;
    for (const std::string& w : s.words) name += (name.empty() ? "" : " ") + w;
    std::fprintf(out, "  %-22s %s\n", name.c_str(), s.summary);
  }
  std::fprintf(out,
               "\nexit codes: 0 success, 1 negative answer (no board, out of tolerance), "
               "2 bad usage or input\n");
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty() || args[0] == "help" || args[0] == "--help" || args[0] == "-h") {
    PrintHelp(stdout);
    return args.empty() ? linecal::cli::kExitBadInput : linecal::cli::kExitOk;
  }
  // The longest subcommand whose words open the argument list wins ("lidar decode").
  const Subcommand* best = nullptr;
  for (const Subcommand& s : Subcommands()) {
    if (s.words.size() > args.size()) continue;
    if (!std::equal(s.words.begin(), s.words.end(), args.begin())) continue;
    if (best == nullptr || s.words.size() > best->words.size()) best = &s;
  }
  if (best == nullptr) {
    std::fprintf(stderr, "linecal: unknown subcommand '%s' (linecal help lists them)\n",
                 args[0].c_str());
    return linecal::cli::kExitBadInput;
  }
  return best->run(linecal::tools::Args(args.begin() + best->words.size(), args.end()));
}
