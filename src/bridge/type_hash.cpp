// See type_hash.h. The descriptions below are the .msg definitions of the
// published types (their ROS 2 packages', and examples/ros2/cdm_msgs for
// cdm's own), field by field; tests/dds recomputes the hashes on its own and
// checks two against the values ROS 2's generated code carries.
#include "type_hash.h"

#include <openssl/evp.h>

#include <map>
#include <set>
#include <vector>

namespace cdm::bridge {

namespace {

// type_description_interfaces/msg/FieldType ids.
enum : int {
    kNested = 1,
    kInt32 = 6,
    kUint32 = 7,
    kUint64 = 9,
    kFloat32 = 10,
    kFloat64 = 11,
    kBool = 15,
    kByte = 16,
    kString = 17,
    kUnboundedSequence = 144, // added to the element's id
};

struct Field {
    const char *name;
    int type_id;
    const char *nested; // the nested type's ROS name, "" for a primitive
};

const std::map<std::string, std::vector<Field>> &types() {
    static const std::map<std::string, std::vector<Field>> t = {
        {"builtin_interfaces/msg/Time", {{"sec", kInt32, ""}, {"nanosec", kUint32, ""}}},
        {"std_msgs/msg/Header", {{"stamp", kNested, "builtin_interfaces/msg/Time"}, {"frame_id", kString, ""}}},
        {"geometry_msgs/msg/Point", {{"x", kFloat64, ""}, {"y", kFloat64, ""}, {"z", kFloat64, ""}}},
        {"geometry_msgs/msg/Quaternion",
         {{"x", kFloat64, ""}, {"y", kFloat64, ""}, {"z", kFloat64, ""}, {"w", kFloat64, ""}}},
        {"geometry_msgs/msg/Pose",
         {{"position", kNested, "geometry_msgs/msg/Point"}, {"orientation", kNested, "geometry_msgs/msg/Quaternion"}}},
        {"geometry_msgs/msg/PoseStamped",
         {{"header", kNested, "std_msgs/msg/Header"}, {"pose", kNested, "geometry_msgs/msg/Pose"}}},
        {"sensor_msgs/msg/Joy",
         {{"header", kNested, "std_msgs/msg/Header"},
          {"axes", kFloat32 + kUnboundedSequence, ""},
          {"buttons", kInt32 + kUnboundedSequence, ""}}},
        {"sensor_msgs/msg/JointState",
         {{"header", kNested, "std_msgs/msg/Header"},
          {"name", kString + kUnboundedSequence, ""},
          {"position", kFloat64 + kUnboundedSequence, ""},
          {"velocity", kFloat64 + kUnboundedSequence, ""},
          {"effort", kFloat64 + kUnboundedSequence, ""}}},
        {"diagnostic_msgs/msg/KeyValue", {{"key", kString, ""}, {"value", kString, ""}}},
        {"diagnostic_msgs/msg/DiagnosticStatus",
         {{"level", kByte, ""},
          {"name", kString, ""},
          {"message", kString, ""},
          {"hardware_id", kString, ""},
          {"values", kNested + kUnboundedSequence, "diagnostic_msgs/msg/KeyValue"}}},
        {"diagnostic_msgs/msg/DiagnosticArray",
         {{"header", kNested, "std_msgs/msg/Header"},
          {"status", kNested + kUnboundedSequence, "diagnostic_msgs/msg/DiagnosticStatus"}}},
        {"cdm_msgs/msg/Status",
         {{"header", kNested, "std_msgs/msg/Header"},
          {"stale", kBool, ""},
          {"disconnected", kBool, ""},
          {"compensated", kBool, ""},
          {"out_of_workspace", kBool, ""},
          {"end_of_stream", kBool, ""},
          {"flags", kUint32, ""},
          {"report_sequence", kUint32, ""},
          {"device_time_us", kUint64, ""},
          {"reports", kUint64, ""},
          {"dropped", kUint64, ""},
          {"malformed", kUint64, ""},
          {"published", kUint64, ""},
          {"skipped", kUint64, ""}}},
    };
    return t;
}

// Every type `name` refers to, directly or not (std::set: sorted by name,
// the order the hashed form lists them in).
void references(const std::string &name, std::set<std::string> &out) {
    for (const Field &f : types().at(name))
        if (*f.nested && out.insert(f.nested).second) references(f.nested, out);
}

// One IndividualTypeDescription as Python's json.dumps(separators=(', ',
// ': ')) writes it; names are plain ASCII identifiers, nothing to escape.
std::string individual(const std::string &name) {
    std::string s = "{\"type_name\": \"" + name + "\", \"fields\": [";
    bool first = true;
    for (const Field &f : types().at(name)) {
        if (!first) s += ", ";
        first = false;
        s += std::string("{\"name\": \"") + f.name + "\", \"type\": {\"type_id\": " + std::to_string(f.type_id) +
             ", \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"" + f.nested + "\"}}";
    }
    return s + "]}";
}

} // namespace

std::string type_description_json(const std::string &ros_type) {
    if (!types().count(ros_type)) return "";
    std::set<std::string> refs;
    references(ros_type, refs);
    std::string s = "{\"type_description\": " + individual(ros_type) + ", \"referenced_type_descriptions\": [";
    bool first = true;
    for (const std::string &r : refs) {
        if (!first) s += ", ";
        first = false;
        s += individual(r);
    }
    return s + "]}";
}

std::string type_hash(const std::string &ros_type) {
    const std::string json = type_description_json(ros_type);
    if (json.empty()) return "";
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int n = 0;
    if (EVP_Digest(json.data(), json.size(), digest, &n, EVP_sha256(), nullptr) != 1 || n != 32) return "";
    static const char hex[] = "0123456789abcdef";
    std::string s = "RIHS01_";
    for (unsigned int i = 0; i < n; ++i) {
        s.push_back(hex[digest[i] >> 4]);
        s.push_back(hex[digest[i] & 15]);
    }
    return s;
}

std::string type_hash_user_data(const std::string &ros_type) {
    const std::string h = type_hash(ros_type);
    return h.empty() ? "" : "typehash=" + h + ";";
}

} // namespace cdm::bridge
