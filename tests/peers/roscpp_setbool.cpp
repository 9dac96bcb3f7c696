// A stock roscpp std_srvs/SetBool server or client for the services tests (no micros_rt: Debian's roscpp).
// Built by the tests (tests/integration/helpers.py: CxxPeerBuild) against libroscpp-dev and libstd-srvs-dev.
//
//     roscpp_setbool server NAME            answers data=true with success=true, "roscpp got true", and
//                                           data=false with success=false, "roscpp got false"
//     roscpp_setbool client NAME N [WAIT]   waits up to WAIT seconds (30) for NAME, then calls it N times with
//                                           data alternating true, false, true, ...
//
// Events, one JSON object per stdout line (flushed), as the Python peers print them:
//   server: {"event": "ready", "node", "name", "pid"}; {"event": "served", "data"} per request
//   client: {"event": "available", "elapsed"} or {"event": "unavailable", "elapsed"} (exit 1);
//           per call {"event": "response", "i", "data", "success", "message", "us"} or {"event": "error", "i",
//           "data", "us"}; then {"event": "summary", "calls", "ok", "failures", "wrong", "p50_us", "p99_us"}
//           ("failures": calls that returned false, "wrong": answers whose success differs from data)
//   both:   {"event": "done"} at the end
// The client is a plain non-persistent ros::ServiceClient: each call asks the master and opens a connection, as
// most roscpp code calls services.

#include <ros/ros.h>
#include <std_srvs/SetBool.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace {

std::string json_string(const std::string& text) {
  std::string out = "\"";
  for (unsigned char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  return out + "\"";
}

const char* boolean(bool value) { return value ? "true" : "false"; }

// fields: the object's members after "event", already JSON ("\"i\": 3, ...")
void emit(const char* event, const std::string& fields = "") {
  std::printf("{\"event\": \"%s\"%s%s}\n", event, fields.empty() ? "" : ", ", fields.c_str());
  std::fflush(stdout);
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double percentile(std::vector<double> values, double q) {
  if (values.empty()) return -1.0;
  std::sort(values.begin(), values.end());
  return values[std::min(values.size() - 1, static_cast<size_t>(q * values.size()))];
}

bool on_set_bool(std_srvs::SetBool::Request& request, std_srvs::SetBool::Response& response) {
  emit("served", std::string("\"data\": ") + boolean(request.data));
  response.success = request.data;
  response.message = request.data ? "roscpp got true" : "roscpp got false";
  return true;
}

int serve(const std::string& name) {
  ros::NodeHandle nh;
  ros::ServiceServer server = nh.advertiseService(name, on_set_bool);  // registered with the master on return
  emit("ready", "\"node\": " + json_string(ros::this_node::getName()) + ", \"name\": " +
                    json_string(ros::names::resolve(name)) + ", \"pid\": " + std::to_string(getpid()));
  ros::spin();  // until SIGINT
  emit("done");
  return 0;
}

int call(const std::string& name, long count, double wait) {
  ros::NodeHandle nh;
  auto t0 = std::chrono::steady_clock::now();
  // ros::service::exists without its log line (rosconsole prints INFO on stdout, which is for JSON here)
  while (!ros::service::exists(name, false)) {
    if (!ros::ok() || seconds_since(t0) >= wait) {
      emit("unavailable", "\"elapsed\": " + std::to_string(seconds_since(t0)));
      return 1;
    }
    ros::Duration(0.02).sleep();
  }
  emit("available", "\"elapsed\": " + std::to_string(seconds_since(t0)));
  ros::ServiceClient client = nh.serviceClient<std_srvs::SetBool>(name);
  std::vector<double> times;
  long failures = 0, wrong = 0;
  for (long i = 0; i < count && ros::ok(); ++i) {
    std_srvs::SetBool srv;
    srv.request.data = i % 2 == 0;
    auto t = std::chrono::steady_clock::now();
    bool ok = client.call(srv);
    double us = seconds_since(t) * 1e6;
    std::string common = "\"i\": " + std::to_string(i) + ", \"data\": " + boolean(srv.request.data) +
                         ", \"us\": " + std::to_string(us);
    if (ok) {
      times.push_back(us);
      if (static_cast<bool>(srv.response.success) != static_cast<bool>(srv.request.data)) ++wrong;
      emit("response", common + ", \"success\": " + boolean(srv.response.success) +
                           ", \"message\": " + json_string(srv.response.message));
    } else {
      ++failures;
      emit("error", common);
    }
  }
  emit("summary", "\"calls\": " + std::to_string(count) + ", \"ok\": " + std::to_string(times.size()) +
                      ", \"failures\": " + std::to_string(failures) + ", \"wrong\": " + std::to_string(wrong) +
                      ", \"p50_us\": " + std::to_string(percentile(times, 0.5)) +
                      ", \"p99_us\": " + std::to_string(percentile(times, 0.99)));
  emit("done");
  return 0;
}

int usage() {
  std::fprintf(stderr, "usage: roscpp_setbool server NAME | roscpp_setbool client NAME N [WAIT_SECONDS]\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  const bool server = mode == "server";
  if (!(server && argc == 3) && !(mode == "client" && (argc == 4 || argc == 5))) return usage();
  ros::init(argc, argv, server ? "roscpp_setbool_server" : "roscpp_setbool_client",
            ros::init_options::AnonymousName | ros::init_options::NoRosout);
  if (server) return serve(argv[2]);
  return call(argv[2], std::strtol(argv[3], nullptr, 10), argc == 5 ? std::strtod(argv[4], nullptr) : 30.0);
}
