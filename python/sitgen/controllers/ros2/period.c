/* One control period of a ros2: run handed over in C: the odometry, the scan and the clock, in
 * that order, each only once every reliable reader of the one before has acknowledged it, and
 * the scan only once the node's threads have gone back to waiting (bridge.py's
 * Bridge.hand_over, whose order and waits this keeps exactly); and the node's answer taken
 * from sitgen's /cmd_vel subscription (Twist or TwistStamped), waiting for it on that
 * subscription alone (Bridge.take).
 *
 * Why: sitgen's side of a period in Python (building three messages, rclpy converting each,
 * reading the node's thread states from /proc) cost about 1 ms, which held a trivial node
 * under 1,000 control steps/s. Here the messages are made once a run and only their stamps,
 * pose, velocity and ranges change; rclpy's own publishers are used (their rcl handles), so
 * the node sees one participant whichever path a period takes.
 *
 * Parameters: the publishers, the period's values (computed in Python, as the Python path
 * computes them), the node's process ids and the settle and acknowledgement bounds (seconds).
 *
 * Source: rcl (rcl_publish, rcl_publisher_wait_for_all_acked, rcl_wait, rcl_take); proc(5)
 * for thread states.
 * Built on first use by native.py with the machine's gcc against the ROS 2 wheels. */

#include <dirent.h>
#include <fcntl.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <geometry_msgs/msg/twist.h>
#include <geometry_msgs/msg/twist_stamped.h>
#include <nav_msgs/msg/odometry.h>
#include <rcl/error_handling.h>
#include <rcl/publisher.h>
#include <rcl/subscription.h>
#include <rcl/wait.h>
#include <rosgraph_msgs/msg/clock.h>
#include <rosidl_runtime_c/primitives_sequence_functions.h>
#include <rosidl_runtime_c/string_functions.h>
#include <sensor_msgs/msg/laser_scan.h>

static nav_msgs__msg__Odometry odom;
static sensor_msgs__msg__LaserScan scan;
static rosgraph_msgs__msg__Clock clock_msg;
static int made = 0;
static char problem[512];

const char * sitgen_period_problem(void) {return problem;}

static int failed(const char * what)
{
  snprintf(problem, sizeof(problem), "%s: %s", what, rcl_get_error_string().str);
  rcl_reset_error();
  return -1;
}

/* The messages' constant fields, once a run (the scan's are the run's laser's). */
int sitgen_period_setup(
  const char * odom_frame, const char * base_frame, const char * scan_frame,
  float angle_min, float angle_max, float angle_increment, float time_increment,
  float scan_time, float range_min, float range_max)
{
  if (!made) {
    if (!nav_msgs__msg__Odometry__init(&odom) || !sensor_msgs__msg__LaserScan__init(&scan) ||
      !rosgraph_msgs__msg__Clock__init(&clock_msg))
    {
      snprintf(problem, sizeof(problem), "the period's messages could not be made");
      return -1;
    }
    made = 1;
  }
  if (!rosidl_runtime_c__String__assign(&odom.header.frame_id, odom_frame) ||
    !rosidl_runtime_c__String__assign(&odom.child_frame_id, base_frame) ||
    !rosidl_runtime_c__String__assign(&scan.header.frame_id, scan_frame))
  {
    snprintf(problem, sizeof(problem), "the frame ids could not be set");
    return -1;
  }
  scan.angle_min = angle_min;
  scan.angle_max = angle_max;
  scan.angle_increment = angle_increment;
  scan.time_increment = time_increment;
  scan.scan_time = scan_time;
  scan.range_min = range_min;
  scan.range_max = range_max;
  return 0;
}

/* --- the node's thread states (proc_tasks.py's wait_idle) ----------------------------------- */

#define MAX_TASKS 1024

typedef struct
{
  int pid;
  int tid;
  int fd;
  int seen;
} task_file;

static task_file tasks[MAX_TASKS];
static int n_tasks = 0;

/* The kept-open stat file of a thread, opened on first sight; NULL where it cannot be. */
static task_file * task_of(int pid, int tid)
{
  for (int i = 0; i < n_tasks; ++i) {
    if (tasks[i].pid == pid && tasks[i].tid == tid) {
      tasks[i].seen = 1;
      return &tasks[i];
    }
  }
  if (n_tasks == MAX_TASKS) {
    return NULL;
  }
  char path[64];
  snprintf(path, sizeof(path), "/proc/%d/task/%d/stat", pid, tid);
  int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    return NULL;
  }
  tasks[n_tasks] = (task_file){pid, tid, fd, 1};
  return &tasks[n_tasks++];
}

/* Whether any thread of the processes is running, runnable or waiting on a device. */
static int any_busy(const int * pids, size_t n_pids)
{
  int busy = 0;
  for (int i = 0; i < n_tasks; ++i) {
    tasks[i].seen = 0;
  }
  for (size_t p = 0; p < n_pids; ++p) {
    char path[48];
    snprintf(path, sizeof(path), "/proc/%d/task", pids[p]);
    DIR * dir = opendir(path);
    if (dir == NULL) {
      continue;
    }
    struct dirent * entry;
    while ((entry = readdir(dir)) != NULL) {
      if (entry->d_name[0] < '0' || entry->d_name[0] > '9') {
        continue;
      }
      task_file * task = task_of(pids[p], atoi(entry->d_name));
      if (task == NULL) {
        continue;
      }
      char stat[1024];
      ssize_t got = pread(task->fd, stat, sizeof(stat) - 1, 0);
      if (got <= 0) {
        /* The thread has exited: its file is given back below, and a thread of a process
         * that has taken its ids since is opened afresh on the next pass (as proc_tasks.py). */
        task->seen = 0;
        continue;
      }
      stat[got] = '\0';
      /* Fast DDS's own threads (dds.*) are not waited for: proc_tasks.py's protocol_thread. */
      char * open_paren = strchr(stat, '(');
      if (open_paren != NULL && strncmp(open_paren + 1, "dds.", 4) == 0) {
        continue;
      }
      char * close_paren = strrchr(stat, ')');
      if (close_paren != NULL && close_paren[1] == ' ' &&
        (close_paren[2] == 'R' || close_paren[2] == 'D'))
      {
        busy = 1;
      }
    }
    closedir(dir);
  }
  /* Threads that have exited (or belong to processes no longer watched) give their files back. */
  int kept = 0;
  for (int i = 0; i < n_tasks; ++i) {
    if (tasks[i].seen) {
      tasks[kept++] = tasks[i];
    } else {
      close(tasks[i].fd);
    }
  }
  n_tasks = kept;
  return busy;
}

static double now_s(void)
{
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static void wait_idle(const int * pids, size_t n_pids, double timeout_s)
{
  double deadline = now_s() + timeout_s;
  while (any_busy(pids, n_pids) && now_s() <= deadline) {
    sched_yield();
  }
}

/* --- the period ---------------------------------------------------------------------------- */

static void wait_acked(const rcl_publisher_t * publisher, double timeout_s)
{
  /* A reader that does not acknowledge in time is handed the next message anyway (the answer's
   * timeout catches a node that stopped reading). */
  if (rcl_publisher_wait_for_all_acked(publisher, (rcl_duration_value_t)(timeout_s * 1e9)) !=
    RCL_RET_OK)
  {
    rcl_reset_error();
  }
}

int sitgen_period_hand_over(
  const rcl_publisher_t * odom_publisher, const rcl_publisher_t * scan_publisher,
  const rcl_publisher_t * clock_publisher,
  int32_t sec, uint32_t nanosec, int32_t clock_sec, uint32_t clock_nanosec,
  double x, double y, double qz, double qw, double v, double omega,
  const float * ranges, size_t n_ranges,
  const int * pids, size_t n_pids, double settle_s, double ack_timeout_s)
{
  if (!made) {
    snprintf(problem, sizeof(problem), "sitgen_period_setup was not called");
    return -1;
  }
  odom.header.stamp.sec = sec;
  odom.header.stamp.nanosec = nanosec;
  odom.pose.pose.position.x = x;
  odom.pose.pose.position.y = y;
  odom.pose.pose.orientation.x = 0.0;
  odom.pose.pose.orientation.y = 0.0;
  odom.pose.pose.orientation.z = qz;
  odom.pose.pose.orientation.w = qw;
  odom.twist.twist.linear.x = v;
  odom.twist.twist.angular.z = omega;
  scan.header.stamp.sec = sec;
  scan.header.stamp.nanosec = nanosec;
  if (scan.ranges.size != n_ranges) {
    rosidl_runtime_c__float__Sequence__fini(&scan.ranges);
    if (!rosidl_runtime_c__float__Sequence__init(&scan.ranges, n_ranges)) {
      snprintf(problem, sizeof(problem), "the scan's %zu ranges could not be held", n_ranges);
      return -1;
    }
  }
  memcpy(scan.ranges.data, ranges, n_ranges * sizeof(float));
  clock_msg.clock.sec = clock_sec;
  clock_msg.clock.nanosec = clock_nanosec;

  if (rcl_publish(odom_publisher, &odom, NULL) != RCL_RET_OK) {
    return failed("publishing the odometry");
  }
  wait_acked(odom_publisher, ack_timeout_s);
  wait_idle(pids, n_pids, settle_s);
  if (rcl_publish(scan_publisher, &scan, NULL) != RCL_RET_OK) {
    return failed("publishing the scan");
  }
  wait_acked(scan_publisher, ack_timeout_s);
  /* Not settled before the clock: a node's executor takes the clock before its other messages
   * of the same turn (bridge.py says why). */
  if (rcl_publish(clock_publisher, &clock_msg, NULL) != RCL_RET_OK) {
    return failed("publishing the clock");
  }
  return 0;
}

/* --- the answer ---------------------------------------------------------------------------- */

static rcl_wait_set_t answers = {0};
static rcl_context_t * answers_context = NULL;
static geometry_msgs__msg__TwistStamped stamped_answer;
static int stamped_made = 0;

/* The wait set goes with the bridge's context: given back before the context is shut down. */
void sitgen_answer_release(void)
{
  if (answers_context != NULL) {
    if (rcl_wait_set_fini(&answers) != RCL_RET_OK) {
      rcl_reset_error();
    }
    answers_context = NULL;
  }
}

static int take_one(const rcl_subscription_t * subscription, int stamped, double * out)
{
  geometry_msgs__msg__Twist twist;
  void * message = stamped ? (void *)&stamped_answer : (void *)&twist;
  rcl_ret_t taken = rcl_take(subscription, message, NULL, NULL);
  if (taken == RCL_RET_SUBSCRIPTION_TAKE_FAILED) {
    rcl_reset_error();
    return 0;
  }
  if (taken != RCL_RET_OK) {
    return failed("taking the answer");
  }
  const geometry_msgs__msg__Twist * got = stamped ? &stamped_answer.twist : &twist;
  out[0] = got->linear.x;
  out[1] = got->angular.z;
  /* 0 for a Twist: an unstamped answer (controller.py's _await_answer reads it so). */
  out[2] = stamped ?
    (double)stamped_answer.header.stamp.sec + (double)stamped_answer.header.stamp.nanosec * 1e-9 :
    0.0;
  return 1;
}

/* The next answer on ``subscription`` (v, omega and its stamp in seconds into ``out``): 1, or 0
 * if none came within ``timeout_ns``, or -1 (sitgen_period_problem says why). */
int sitgen_answer_take(
  const rcl_subscription_t * subscription, rcl_context_t * context, int stamped,
  int64_t timeout_ns, double * out)
{
  if (stamped && !stamped_made) {
    if (!geometry_msgs__msg__TwistStamped__init(&stamped_answer)) {
      snprintf(problem, sizeof(problem), "the answer's message could not be made");
      return -1;
    }
    stamped_made = 1;
  }
  int got = take_one(subscription, stamped, out);
  if (got != 0 || timeout_ns <= 0) {
    return got;
  }
  if (answers_context != context) {
    sitgen_answer_release();
    answers = rcl_get_zero_initialized_wait_set();
    if (rcl_wait_set_init(&answers, 1, 0, 0, 0, 0, 0, context, rcl_get_default_allocator()) !=
      RCL_RET_OK)
    {
      return failed("making the answer's wait set");
    }
    answers_context = context;
  }
  if (rcl_wait_set_clear(&answers) != RCL_RET_OK ||
    rcl_wait_set_add_subscription(&answers, subscription, NULL) != RCL_RET_OK)
  {
    return failed("waiting for the answer");
  }
  rcl_ret_t waited = rcl_wait(&answers, timeout_ns);
  if (waited == RCL_RET_TIMEOUT) {
    rcl_reset_error();
    return 0;
  }
  if (waited != RCL_RET_OK) {
    return failed("waiting for the answer");
  }
  return take_one(subscription, stamped, out);
}
