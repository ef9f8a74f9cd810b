// The gRPC API as station integrators rely on it (docs/interfaces.md): the service and its methods,
// which of them stream, and the house rule that units live in field names (docs/conventions.md).
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "linecal/v1/station.grpc.pb.h"

namespace linecal {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::FileDescriptor;

const FileDescriptor* ApiFile() { return v1::StartCycleRequest::descriptor()->file(); }

TEST(ProtoApiTest, StationServiceHasTheMethodsOfInterfacesMd) {
  const FileDescriptor* file = ApiFile();
  EXPECT_EQ(file->package(), "linecal.v1");
  ASSERT_EQ(file->service_count(), 1);
  const auto* service = file->service(0);
  EXPECT_EQ(service->full_name(), "linecal.v1.Station");
  EXPECT_EQ(std::string(v1::Station::service_full_name()), "linecal.v1.Station");

  const std::set<std::string> expected = {"StartCycle", "WatchCycle",  "GetCycle",
                                          "ListCycles", "CancelCycle", "GetStationStatus"};
  std::set<std::string> actual;
  for (int i = 0; i < service->method_count(); ++i) {
    const auto* m = service->method(i);
    actual.insert(m->name());
    EXPECT_FALSE(m->client_streaming()) << m->name();
    // Only watching a cycle streams: the rest are single request, single answer.
    EXPECT_EQ(m->server_streaming(), m->name() == "WatchCycle") << m->name();
  }
  EXPECT_EQ(actual, expected);
}

TEST(ProtoApiTest, StartCycleRequestRoundTripsOnTheWire) {
  v1::StartCycleRequest request;
  request.set_vin("WVWZZZ1JZXW000001");
  request.set_car_model_id("reference");
  request.mutable_aligner()->set_lateral_offset_m(-0.012);
  request.mutable_aligner()->set_longitudinal_offset_m(0.031);
  request.mutable_aligner()->set_thrust_angle_deg(0.08);
  request.mutable_options()->set_record_capture(true);
  request.mutable_options()->set_frames_per_sensor(3);

  const std::string wire = request.SerializeAsString();
  v1::StartCycleRequest back;
  ASSERT_TRUE(back.ParseFromString(wire));
  EXPECT_EQ(back.vin(), "WVWZZZ1JZXW000001");
  EXPECT_EQ(back.car_model_id(), "reference");
  EXPECT_EQ(back.aligner().lateral_offset_m(), -0.012);
  EXPECT_EQ(back.aligner().longitudinal_offset_m(), 0.031);
  EXPECT_EQ(back.aligner().thrust_angle_deg(), 0.08);
  EXPECT_TRUE(back.options().record_capture());
  EXPECT_EQ(back.options().frames_per_sensor(), 3u);
}

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Every floating-point field carries its unit in its name, and every time is int64 _ns.
// The exceptions are unitless by nature: matrix entries and residuals whose unit is the
// sensor kind's (documented on the field). Multiples of a standard deviation end in _sigmas.
TEST(ProtoApiTest, UnitsAreInTheFieldNames) {
  const std::set<std::string> unitless = {
      "linecal.v1.Transform.m", "linecal.v1.SensorResult.ground_homography",
      "linecal.v1.SensorResult.residual_rms", "linecal.v1.ShiftedSensor.baseline_residual",
      "linecal.v1.ShiftedSensor.recent_residual"};
  const FileDescriptor* file = ApiFile();
  int checked = 0;
  for (int i = 0; i < file->message_type_count(); ++i) {
    const Descriptor* message = file->message_type(i);
    for (int f = 0; f < message->field_count(); ++f) {
      const FieldDescriptor* field = message->field(f);
      const std::string& name = field->name();
      if (EndsWith(name, "_ns")) {
        EXPECT_EQ(field->type(), FieldDescriptor::TYPE_INT64) << field->full_name();
      }
      if (field->type() != FieldDescriptor::TYPE_DOUBLE || unitless.count(field->full_name()))
        continue;
      ++checked;
      EXPECT_TRUE(EndsWith(name, "_m") || EndsWith(name, "_deg") || EndsWith(name, "_px") ||
                  EndsWith(name, "_sigmas"))
          << field->full_name() << " has no unit suffix";
    }
  }
  // Aligner (3), mounting angles (6), ranging (2), vanishing point (2), the moved-target
  // alarm's statistic, limit and shifts (3).
  EXPECT_EQ(checked, 16);
}

}  // namespace
}  // namespace linecal
