/* A ros2: node with a trivial reply, on rcl (ROS 2's C client library, in the rclpy wheels):
 * one constant command for each scan, nothing else. make bench compiles it with the machine's
 * gcc against the wheels' headers and drives it in lockstep beside benches/trivial_node.py:
 * what a step costs with it is sitgen's side of the lockstep and DDS, with next to nothing of
 * the node's own (no executor, no Python). */

#include <stdio.h>
#include <stdlib.h>

#include <rcl/error_handling.h>
#include <rcl/rcl.h>
#include <rmw/qos_profiles.h>
#include <geometry_msgs/msg/twist.h>
#include <sensor_msgs/msg/laser_scan.h>

#define CHECK(call) \
  do { \
    if ((call) != RCL_RET_OK) { \
      fprintf(stderr, "trivial_node: %s failed: %s\n", #call, rcl_get_error_string().str); \
      return 1; \
    } \
  } while (0)

int main(int argc, char ** argv)
{
  rcl_allocator_t allocator = rcl_get_default_allocator();
  rcl_init_options_t init_options = rcl_get_zero_initialized_init_options();
  CHECK(rcl_init_options_init(&init_options, allocator));
  rcl_context_t context = rcl_get_zero_initialized_context();
  CHECK(rcl_init(argc, (const char * const *)argv, &init_options, &context));

  rcl_node_t node = rcl_get_zero_initialized_node();
  rcl_node_options_t node_options = rcl_node_get_default_options();
  CHECK(rcl_node_init(&node, "trivial_node_c", "", &context, &node_options));

  rcl_publisher_t cmd = rcl_get_zero_initialized_publisher();
  rcl_publisher_options_t cmd_options = rcl_publisher_get_default_options();
  CHECK(rcl_publisher_init(
      &cmd, &node, ROSIDL_GET_MSG_TYPE_SUPPORT(geometry_msgs, msg, Twist), "/cmd_vel",
      &cmd_options));

  rcl_subscription_t scans = rcl_get_zero_initialized_subscription();
  rcl_subscription_options_t scan_options = rcl_subscription_get_default_options();
  scan_options.qos = rmw_qos_profile_sensor_data;
  CHECK(rcl_subscription_init(
      &scans, &node, ROSIDL_GET_MSG_TYPE_SUPPORT(sensor_msgs, msg, LaserScan), "/scan",
      &scan_options));

  rcl_wait_set_t wait_set = rcl_get_zero_initialized_wait_set();
  CHECK(rcl_wait_set_init(&wait_set, 1, 0, 0, 0, 0, 0, &context, allocator));

  geometry_msgs__msg__Twist command;
  geometry_msgs__msg__Twist__init(&command);
  command.linear.x = 0.3;
  command.angular.z = 0.1;
  sensor_msgs__msg__LaserScan scan;
  sensor_msgs__msg__LaserScan__init(&scan);

  for (;;) {  /* until sitgen ends the process (SIGINT, then SIGKILL) */
    CHECK(rcl_wait_set_clear(&wait_set));
    CHECK(rcl_wait_set_add_subscription(&wait_set, &scans, NULL));
    rcl_ret_t woke = rcl_wait(&wait_set, RCL_S_TO_NS(1));
    if (woke == RCL_RET_TIMEOUT) {
      continue;
    }
    CHECK(woke);
    rmw_message_info_t info;
    while (rcl_take(&scans, &scan, &info, NULL) == RCL_RET_OK) {
      CHECK(rcl_publish(&cmd, &command, NULL));
    }
  }
}
