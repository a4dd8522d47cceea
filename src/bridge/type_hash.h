// ROS 2 type hashes (REP-2011, "RIHS01"): the SHA-256 of a type's
// description (its fields and those of every type it refers to, default
// values left out) serialised as rosidl_generator_type_description does.
// rmw_cyclonedds puts "typehash=RIHS01_<hex>;" in each writer's USER_DATA;
// a ROS 2 reader without it warns and `ros2 topic info -v` shows none.
#pragma once

#include <string>

namespace cdm::bridge {

// The ROS 2 types the bridge publishes, by ROS name ("pkg/msg/Type").
// Empty for a type it does not know.
std::string type_description_json(const std::string &ros_type);
// "RIHS01_" and 64 lowercase hex digits; empty for an unknown type.
std::string type_hash(const std::string &ros_type);
// The USER_DATA of a writer of `ros_type`: "typehash=RIHS01_...;".
std::string type_hash_user_data(const std::string &ros_type);

} // namespace cdm::bridge
