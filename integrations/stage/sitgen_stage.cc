// sitgen_stage: a Stage 4.3 controller plugin that drives every robot of a world exported by
// sitgen (`sitgen export -f stage`) with sitgen's own controller, and logs each step.
//
// What it does. Each robot of the world names `ctrl "sitgen_stage ID"`. For each, the plugin
// starts `sitgen serve-controller situation.json --run-spec run.json --robot ID` (the command
// can be replaced with SITGEN_STAGE_CONTROLLER) and speaks sitgen's JSON-lines controller
// protocol to it (docs/controller-protocol.md), with the roles of that document reversed: the
// plugin is the simulator, the sitgen process the controller. At the end of every Stage update
// it observes every robot (pose, velocity, stall, and for robots with a laser a fresh scan and
// the robots the scan sees), asks each controller for its command, sets it, and appends the
// step to `stage-log.jsonl` (or SITGEN_STAGE_LOG), which `sitgen crosscheck` reads.
//
// Why this way. sitgen's step is: observe the world as the last step left it, decide, move.
// Stage's update raytraces before it moves, so a controller reading Stage's own published scan
// would act on a scan one step old. So the plugin traces the scan itself, after the move, with
// the ranger's own Sensor::Update. Stage keeps two raster layers and a raytrace reads the one
// the last move did not write; the plugin re-rasterises every robot into that layer first, so
// scans (and the next update's collision tests) see every robot where it now is, as sitgen's
// do. Speaking the protocol to a separate sitgen process keeps sitgen's code out of this
// GPL-linked plugin and reuses the one protocol every external controller already speaks.
//
// Parameters: the robot id in the ctrl string; SITGEN_STAGE_CONTROLLER (command prefix,
// default `sitgen serve-controller`), SITGEN_STAGE_LOG (default `stage-log.jsonl`). Paths are
// relative to the working directory: run Stage from the export folder.
//
// Source: Stage 4.3 libstage (world.cc World::Update, model_position.cc Move, model_ranger.cc
// Sensor::Update), examples/ctrl/wander.cc for the plugin interface.

#include <stage.hh>

#include <nlohmann/json.hpp>

#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

using json = nlohmann::json;
using namespace Stg;

namespace {

// Robot `id` reads as intensity id + 2 in a scan (the export sets ranger_return so); terrain 1.
constexpr int kRobotReturnBase = 2;

// Model::MapWithChildren / UnMapWithChildren are protected; a pointer to them formed in a
// derived class may be called on any Model.
struct Raster : Model {
  static void Refresh(Model *m, unsigned int layer)
  {
    void (Model::*unmap)(unsigned int) = &Raster::UnMapWithChildren;
    void (Model::*map)(unsigned int) = &Raster::MapWithChildren;
    (m->*unmap)(layer);
    (m->*map)(layer);
  }
};

// One sitgen controller process, spoken to over pipes, one JSON object per line each way.
class Controller {
public:
  explicit Controller(const std::string &command)
  {
    int to_child[2], from_child[2];
    if (pipe(to_child) != 0 || pipe(from_child) != 0)
      Fail("cannot make pipes for `" + command + "`");
    pid_ = fork();
    if (pid_ < 0)
      Fail("cannot fork for `" + command + "`");
    if (pid_ == 0) {
      dup2(to_child[0], 0);
      dup2(from_child[1], 1);
      close(to_child[1]);
      close(from_child[0]);
      execl("/bin/sh", "sh", "-c", ("exec " + command).c_str(), (char *)nullptr);
      _exit(127);
    }
    close(to_child[0]);
    close(from_child[1]);
    out_ = fdopen(to_child[1], "w");
    in_ = fdopen(from_child[0], "r");
    command_ = command;
  }

  ~Controller()
  {
    if (out_) {
      fputs("{\"type\": \"end\"}\n", out_);
      fclose(out_);
    }
    if (in_)
      fclose(in_);
    if (pid_ > 0)
      waitpid(pid_, nullptr, 0);
  }

  json Ask(const json &message)
  {
    const std::string line = message.dump() + "\n";
    if (fputs(line.c_str(), out_) == EOF || fflush(out_) != 0)
      Fail("`" + command_ + "` stopped reading its input");
    char *buf = nullptr;
    size_t cap = 0;
    const ssize_t n = getline(&buf, &cap, in_);
    std::string reply = n > 0 ? std::string(buf, n) : std::string();
    free(buf);
    if (n <= 0)
      Fail("`" + command_ + "` closed its output (see its stderr above)");
    json j = json::parse(reply, nullptr, false);
    if (j.is_discarded() || !j.is_object())
      Fail("`" + command_ + "` sent a reply that is not a JSON object: " + reply);
    if (j.contains("error"))
      Fail("`" + command_ + "`: " + j["error"].dump());
    return j;
  }

  [[noreturn]] static void Fail(const std::string &why)
  {
    fprintf(stderr, "sitgen_stage: %s\n", why.c_str());
    exit(1);
  }

private:
  pid_t pid_ = -1;
  FILE *out_ = nullptr;
  FILE *in_ = nullptr;
  std::string command_;
};

struct Robot {
  int id;
  ModelPosition *position;
  ModelRanger *laser; // null for a robot without one
  std::unique_ptr<Controller> controller;
};

// Every robot of the world, by id; one world-update callback serves them all.
struct Plugin {
  std::map<int, Robot> robots;
  std::ofstream log;
  World *world = nullptr;
  double dt_s = 0.1;
  uint64_t step = 0;
};

Plugin &plugin()
{
  static Plugin p;
  return p;
}

std::string Env(const char *name, const char *fallback)
{
  const char *v = getenv(name);
  return v && *v ? std::string(v) : std::string(fallback);
}

// A fresh scan from where the robot is now: ranges, and the ids of the robots some beam hits
// first, in beam order.
std::pair<std::vector<double>, std::vector<int> > Scan(ModelRanger *laser)
{
  std::vector<double> ranges;
  std::vector<int> seen;
  for (ModelRanger::Sensor &s : laser->GetSensorsMutable()) {
    s.Update(laser);
    for (size_t t = 0; t < s.ranges.size(); t++) {
      ranges.push_back(s.ranges[t]);
      const int id = (int)std::lround(s.intensities[t]) - kRobotReturnBase;
      if (id >= 0 && plugin().robots.count(id)) {
        bool known = false;
        for (int k : seen)
          known = known || k == id;
        if (!known)
          seen.push_back(id);
      }
    }
  }
  return { ranges, seen };
}

json PoseOf(const ModelPosition *m)
{
  const Pose p = m->GetGlobalPose();
  return json::array({ p.x, p.y, p.a });
}

// At the end of every Stage update: observe, decide, command, log.
int WorldUpdate(World *world, void *)
{
  Plugin &p = plugin();
  // Stage's first update moves nothing (no command was set yet): it is sitgen's start, step 0.
  const double time_s = (double)p.step * p.dt_s;
  const unsigned int read_layer = (world->UpdateCount() + 1) % 2;
  for (auto &[id, r] : p.robots)
    Raster::Refresh(r.position, read_layer);

  json entry = { { "step", p.step }, { "time", time_s }, { "robots", json::array() } };
  for (auto &[id, r] : p.robots) {
    const Velocity v = r.position->GetVelocity();
    json obs = { { "type", "observation" },
                 { "time", time_s },
                 { "pose", PoseOf(r.position) },
                 { "velocity", json::array({ v.x, v.a }) },
                 { "stalled", r.position->Stalled() } };
    json logged = { { "id", id },
                    { "pose", obs["pose"] },
                    { "velocity", obs["velocity"] },
                    { "stalled", obs["stalled"] } };
    if (r.laser) {
      auto [ranges, seen] = Scan(r.laser);
      json tracks = json::array();
      for (int o : seen) {
        const ModelPosition *other = p.robots.at(o).position;
        const Pose op = other->GetGlobalPose();
        const double ov = other->GetVelocity().x;
        tracks.push_back({ { "id", o },
                           { "position", json::array({ op.x, op.y }) },
                           { "velocity", json::array({ ov * std::cos(op.a), ov * std::sin(op.a) }) } });
      }
      obs["ranges"] = ranges;
      obs["tracks"] = tracks;
      logged["ranges"] = ranges;
      logged["seen"] = seen;
    }
    const json reply = r.controller->Ask(obs);
    if (!reply.contains("v") || !reply.contains("omega") || !reply["v"].is_number()
        || !reply["omega"].is_number())
      Controller::Fail("robot " + std::to_string(id) + ": a reply without numbers v and omega: "
                       + reply.dump());
    const double cv = reply["v"], cw = reply["omega"];
    r.position->SetSpeed(cv, 0, cw);
    logged["command"] = json::array({ cv, cw });
    entry["robots"].push_back(logged);
  }
  p.log << entry.dump() << "\n";
  p.log.flush();
  p.step++;
  return 0;
}

} // namespace

// Stage calls this once for each model that names the plugin.
extern "C" int Init(Model *mod, CtrlArgs *args)
{
  Plugin &p = plugin();
  std::istringstream words(args->worldfile);
  std::string lib;
  int id = -1;
  words >> lib >> id;
  auto *position = dynamic_cast<ModelPosition *>(mod);
  if (!position || id < 0)
    Controller::Fail(std::string("`ctrl \"") + args->worldfile
                     + "\"` must be on a position model and name its robot id");
  ModelRanger *laser = nullptr;
  for (Model *child : mod->GetChildren())
    if (auto *r = dynamic_cast<ModelRanger *>(child))
      laser = r;
  if (!p.world) {
    signal(SIGPIPE, SIG_IGN); // a controller that dies is reported, not a silent kill
    p.world = mod->GetWorld();
    p.dt_s = (double)p.world->sim_interval / 1e6;
    const std::string log = Env("SITGEN_STAGE_LOG", "stage-log.jsonl");
    p.log.open(log, std::ios::trunc);
    if (!p.log)
      Controller::Fail("cannot write the log " + log);
    p.world->AddUpdateCallback(WorldUpdate, nullptr);
  }
  const std::string command = Env("SITGEN_STAGE_CONTROLLER", "sitgen serve-controller")
      + " situation.json --run-spec run.json --robot " + std::to_string(id);
  Robot robot{ id, position, laser, std::make_unique<Controller>(command) };
  robot.controller->Ask({ { "type", "reset" }, { "robot_id", id } });
  position->Subscribe(); // a position model nobody subscribes to is held still
  p.robots.emplace(id, std::move(robot));
  return 0;
}
