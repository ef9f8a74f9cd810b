// Camera intrinsics from OpenCV, ROS, Kalibr and linecal car model files
// (station/model/camera_intrinsics_file.h): every format, pinhole and fisheye, and the errors,
// each naming the file and the key.
#include "station/model/camera_intrinsics_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace linecal {
namespace {

// What OpenCV's calibration sample writes (cv::FileStorage, YAML), with a strong barrel lens.
constexpr char kOpenCvYaml[] = R"(%YAML:1.0
---
calibration_time: "Sun 06 Dec 2026 05:00:00 UTC"
image_width: 1280
image_height: 720
flags: 0
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1.0005000000000000e+03, 0., 6.4025000000000000e+02, 0.,
       9.9950000000000000e+02, 3.5875000000000000e+02, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ -3.0000000000000000e-01, 1.2e-01, 1.0e-04, -2.0e-04,
       -2.5e-02 ]
avg_reprojection_error: 1.2e-01
)";

// The same camera as a ROS camera_info file (camera_calibration_parsers' layout).
constexpr char kRosYaml[] = R"(image_width: 1280
image_height: 720
camera_name: front
camera_matrix:
  rows: 3
  cols: 3
  data: [1000.5, 0, 640.25, 0, 999.5, 358.75, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.3, 0.12, 0.0001, -0.0002, -0.025]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [1000.5, 0, 640.25, 0, 0, 999.5, 358.75, 0, 0, 0, 1, 0]
)";

// A Kalibr camchain of a pinhole (radtan) and a fisheye (equidistant) camera.
constexpr char kKalibrYaml[] = R"(cam0:
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.3, 0.12, 0.0001, -0.0002]
  distortion_model: radtan
  intrinsics: [1000.5, 999.5, 640.25, 358.75]
  resolution: [1280, 720]
  rostopic: /cam0/image_raw
cam1:
  T_cn_cnm1:
  - [1.0, 0.0, 0.0, -0.11]
  - [0.0, 1.0, 0.0, 0.0]
  - [0.0, 0.0, 1.0, 0.0]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [0]
  camera_model: pinhole
  distortion_coeffs: [0.02, -0.01, 0.003, -0.0005]
  distortion_model: equidistant
  intrinsics: [420.0, 421.0, 639.5, 399.5]
  resolution: [1280, 800]
  rostopic: /cam1/image_raw
)";

// The strong barrel lens of the three files above.
void ExpectFrontCamera(const CameraIntrinsics& in, bool has_k3) {
  EXPECT_EQ(in.type, CameraModelType::kPinhole);
  EXPECT_EQ(in.width, 1280);
  EXPECT_EQ(in.height, 720);
  EXPECT_EQ(in.fx, 1000.5);
  EXPECT_EQ(in.fy, 999.5);
  EXPECT_EQ(in.cx, 640.25);
  EXPECT_EQ(in.cy, 358.75);
  EXPECT_EQ(in.k1, -0.3);
  EXPECT_EQ(in.k2, 0.12);
  EXPECT_EQ(in.p1, 0.0001);
  EXPECT_EQ(in.p2, -0.0002);
  EXPECT_EQ(in.k3, has_k3 ? -0.025 : 0.0);
  EXPECT_EQ(in.k4, 0.0);
}

// The message of a failed parse of `text` (empty when it parsed).
std::string ErrorOf(const std::string& text, const std::string& camera = "") {
  const absl::StatusOr<CameraIntrinsics> in = ParseCameraIntrinsics(text, "cal.yaml", camera);
  if (in.ok()) return "";
  EXPECT_EQ(in.status().code(), absl::StatusCode::kInvalidArgument);
  return std::string(in.status().message());
}

// `text` with the first `from` replaced by `to` (which must be there).
std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return at == std::string::npos ? text : text.replace(at, from.size(), to);
}

TEST(CameraIntrinsicsFileTest, OpenCvYamlPinhole) {
  const absl::StatusOr<CameraIntrinsics> in = ParseCameraIntrinsics(kOpenCvYaml, "cal.yaml", "");
  ASSERT_TRUE(in.ok()) << in.status();
  ExpectFrontCamera(*in, true);
}

TEST(CameraIntrinsicsFileTest, OpenCvYamlFisheyeByItsDistortionModel) {
  std::string text = Replace(kOpenCvYaml, "flags: 0", "distortion_model: fisheye");
  text = Replace(text, "rows: 5", "rows: 4");
  text = Replace(text, "-3.0000000000000000e-01, 1.2e-01, 1.0e-04, -2.0e-04,\n       -2.5e-02",
                 "0.05, -0.01, 0.002, -0.0003");
  const absl::StatusOr<CameraIntrinsics> in = ParseCameraIntrinsics(text, "cal.yaml", "");
  ASSERT_TRUE(in.ok()) << in.status();
  EXPECT_EQ(in->type, CameraModelType::kFisheye);
  EXPECT_EQ(in->fx, 1000.5);
  EXPECT_EQ(in->k1, 0.05);
  EXPECT_EQ(in->k2, -0.01);
  EXPECT_EQ(in->k3, 0.002);
  EXPECT_EQ(in->k4, -0.0003);
  EXPECT_EQ(in->p1, 0.0);
  EXPECT_EQ(in->p2, 0.0);
}

// What OpenCV's camera calibration tutorial writes for cv::fisheye: fisheye_model 1.
TEST(CameraIntrinsicsFileTest, OpenCvTutorialFisheyeModelFlag) {
  std::string text = Replace(kOpenCvYaml, "flags: 0", "flags: 0\nfisheye_model: 1");
  text = Replace(text, "rows: 5", "rows: 4");
  text = Replace(text, "-3.0000000000000000e-01, 1.2e-01, 1.0e-04, -2.0e-04,\n       -2.5e-02",
                 "0.05, -0.01, 0.002, -0.0003");
  const absl::StatusOr<CameraIntrinsics> in = ParseCameraIntrinsics(text, "cal.yaml", "");
  ASSERT_TRUE(in.ok()) << in.status();
  EXPECT_EQ(in->type, CameraModelType::kFisheye);
  EXPECT_EQ(in->k4, -0.0003);
  // fisheye_model 0 is the pinhole, as without the key.
  const absl::StatusOr<CameraIntrinsics> pinhole =
      ParseCameraIntrinsics(Replace(kOpenCvYaml, "flags: 0", "fisheye_model: 0"), "cal.yaml", "");
  ASSERT_TRUE(pinhole.ok()) << pinhole.status();
  ExpectFrontCamera(*pinhole, true);
  EXPECT_EQ(ErrorOf(Replace(text, "fisheye_model: 1", "fisheye_model: 2")),
            "cal.yaml: fisheye_model: must be 0 or 1, got 2");
  EXPECT_EQ(ErrorOf(Replace(text, "fisheye_model: 1",
                            "fisheye_model: 1\ndistortion_model: "
                            "plumb_bob")),
            "cal.yaml: fisheye_model: 1 contradicts distortion_model, a pinhole");
}

// cv::FileStorage's JSON form, with OpenCV's four-coefficient vector (no k3).
TEST(CameraIntrinsicsFileTest, OpenCvJson) {
  constexpr char kJson[] = R"({
    "image_width": 1280,
    "image_height": 720,
    "camera_matrix": {
        "type_id": "opencv-matrix", "rows": 3, "cols": 3, "dt": "d",
        "data": [ 1.0005e+03, 0., 6.4025e+02, 0., 9.995e+02, 3.5875e+02, 0., 0., 1. ]
    },
    "distortion_coefficients": {
        "type_id": "opencv-matrix", "rows": 1, "cols": 4, "dt": "d",
        "data": [ -0.3, 0.12, 1.0e-04, -2.0e-04 ]
    }
})";
  const absl::StatusOr<CameraIntrinsics> in = ParseCameraIntrinsics(kJson, "cal.json", "");
  ASSERT_TRUE(in.ok()) << in.status();
  ExpectFrontCamera(*in, false);
}

TEST(CameraIntrinsicsFileTest, RosPlumbBobWithItsCameraName) {
  const absl::StatusOr<CameraIntrinsics> in = ParseCameraIntrinsics(kRosYaml, "front.yaml", "");
  ASSERT_TRUE(in.ok()) << in.status();
  ExpectFrontCamera(*in, true);
  EXPECT_TRUE(ParseCameraIntrinsics(kRosYaml, "front.yaml", "front").ok());
  EXPECT_EQ(ErrorOf(kRosYaml, "rear"), "cal.yaml: camera_name: 'front', not 'rear'");
  EXPECT_EQ(ErrorOf(kOpenCvYaml, "front"),
            "cal.yaml: holds one camera without a name, not 'front'");
}

// rational_polynomial's eight coefficients are taken when k4..k6 are 0, refused otherwise.
TEST(CameraIntrinsicsFileTest, RosRationalPolynomialNeedsZeroRationalTerms) {
  std::string text = Replace(kRosYaml, "plumb_bob", "rational_polynomial");
  text = Replace(text, "cols: 5", "cols: 8");
  const std::string zero = Replace(text, "-0.025]", "-0.025, 0, 0, 0]");
  const absl::StatusOr<CameraIntrinsics> in = ParseCameraIntrinsics(zero, "cal.yaml", "");
  ASSERT_TRUE(in.ok()) << in.status();
  ExpectFrontCamera(*in, true);
  EXPECT_EQ(ErrorOf(Replace(text, "-0.025]", "-0.025, 0.01, 0, 0]")),
            "cal.yaml: distortion_coefficients: k4 = 0.01: linecal's pinhole has no rational, "
            "thin-prism or tilt terms (k1 k2 p1 p2 k3 only)");
}

TEST(CameraIntrinsicsFileTest, RosEquidistantIsAFisheye) {
  std::string text = Replace(kRosYaml, "plumb_bob", "equidistant");
  text = Replace(text, "cols: 5", "cols: 4");
  text = Replace(text, "[-0.3, 0.12, 0.0001, -0.0002, -0.025]", "[0.1, -0.02, 0.003, -0.0004]");
  const absl::StatusOr<CameraIntrinsics> in = ParseCameraIntrinsics(text, "cal.yaml", "");
  ASSERT_TRUE(in.ok()) << in.status();
  EXPECT_EQ(in->type, CameraModelType::kFisheye);
  EXPECT_EQ(in->k1, 0.1);
  EXPECT_EQ(in->k4, -0.0004);
  // A fisheye has four coefficients, not five.
  EXPECT_EQ(ErrorOf(Replace(kRosYaml, "plumb_bob", "equidistant")),
            "cal.yaml: distortion_coefficients: 5 coefficients; the fisheye takes 4 "
            "(k1 k2 k3 k4)");
}

TEST(CameraIntrinsicsFileTest, KalibrCamchainPicksTheCameraByName) {
  const absl::StatusOr<CameraIntrinsics> cam0 =
      ParseCameraIntrinsics(kKalibrYaml, "c.yaml", "cam0");
  ASSERT_TRUE(cam0.ok()) << cam0.status();
  ExpectFrontCamera(*cam0, false);
  const absl::StatusOr<CameraIntrinsics> cam1 =
      ParseCameraIntrinsics(kKalibrYaml, "c.yaml", "cam1");
  ASSERT_TRUE(cam1.ok()) << cam1.status();
  EXPECT_EQ(cam1->type, CameraModelType::kFisheye);
  EXPECT_EQ(cam1->width, 1280);
  EXPECT_EQ(cam1->height, 800);
  EXPECT_EQ(cam1->fx, 420.0);
  EXPECT_EQ(cam1->fy, 421.0);
  EXPECT_EQ(cam1->cx, 639.5);
  EXPECT_EQ(cam1->cy, 399.5);
  EXPECT_EQ(cam1->k1, 0.02);
  EXPECT_EQ(cam1->k2, -0.01);
  EXPECT_EQ(cam1->k3, 0.003);
  EXPECT_EQ(cam1->k4, -0.0005);
  EXPECT_EQ(ErrorOf(kKalibrYaml), "cal.yaml: holds several cameras (cam0, cam1): name one of them");
  EXPECT_EQ(ErrorOf(kKalibrYaml, "cam2"), "cal.yaml: no camera 'cam2' (cameras: cam0, cam1)");
  // One camera needs no name.
  const std::string one = kKalibrYaml;
  EXPECT_TRUE(ParseCameraIntrinsics(one.substr(0, one.find("cam1:")), "c.yaml", "").ok());
  EXPECT_EQ(ErrorOf(Replace(kKalibrYaml, "camera_model: pinhole", "camera_model: omni"), "cam0"),
            "cal.yaml: cam0.camera_model: 'omni' is not supported: linecal takes Kalibr's pinhole "
            "cameras (radtan, equidistant or none)");
  EXPECT_EQ(
      ErrorOf(Replace(kKalibrYaml, "[1000.5, 999.5, 640.25, 358.75]", "[1000.5, 640.25]"), "cam0"),
      "cal.yaml: cam0.intrinsics: 2 numbers; a pinhole has 4 (fu fv pu pv)");
}

// The reference car model of deploy/: a pinhole and fisheyes among LiDARs and radars.
TEST(CameraIntrinsicsFileTest, CarModelCameraByName) {
  const std::string car = std::string(LINECAL_SOURCE_DIR) + "/deploy/cars/reference.json";
  const absl::StatusOr<CameraIntrinsics> front = ReadCameraIntrinsicsFile(car, "front_camera");
  ASSERT_TRUE(front.ok()) << front.status();
  EXPECT_EQ(front->type, CameraModelType::kPinhole);
  EXPECT_EQ(front->width, 1920);
  EXPECT_EQ(front->fx, 1400.0);
  EXPECT_EQ(front->k1, -0.12);
  const absl::StatusOr<CameraIntrinsics> surround = ReadCameraIntrinsicsFile(car, "surround_front");
  ASSERT_TRUE(surround.ok()) << surround.status();
  EXPECT_EQ(surround->type, CameraModelType::kFisheye);
  const absl::StatusOr<CameraIntrinsics> none = ReadCameraIntrinsicsFile(car, "");
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.status().message(),
            car +
                ": holds several cameras (front_camera, surround_front, surround_rear, "
                "surround_left, surround_right): name one of them");
  // A LiDAR is not a camera.
  const absl::StatusOr<CameraIntrinsics> lidar = ReadCameraIntrinsicsFile(car, "roof_lidar");
  ASSERT_FALSE(lidar.ok());
  EXPECT_NE(lidar.status().message().find("no camera 'roof_lidar' (cameras: front_camera, "),
            std::string::npos)
      << lidar.status();
}

TEST(CameraIntrinsicsFileTest, MissingKeysAreNamed) {
  EXPECT_EQ(ErrorOf(Replace(kOpenCvYaml, "image_height: 720\n", "")),
            "cal.yaml: image_height: missing");
  EXPECT_EQ(ErrorOf(Replace(kRosYaml, "distortion_coefficients:", "distortion:")),
            "cal.yaml: distortion_coefficients: missing");
  EXPECT_EQ(
      ErrorOf(Replace(kRosYaml, "  data: [1000.5, 0, 640.25, 0, 999.5, 358.75, 0, 0, 1]\n", "")),
      "cal.yaml: camera_matrix.data: missing");
  EXPECT_EQ(ErrorOf(Replace(kKalibrYaml, "  resolution: [1280, 720]\n", ""), "cam0"),
            "cal.yaml: cam0.resolution: missing");
  EXPECT_EQ(ErrorOf("calibration_time: now\nimage_width: 640\n"),
            "cal.yaml: not a camera calibration: no camera_matrix (OpenCV, ROS), cam0 (Kalibr) "
            "or sensors (linecal car model)");
}

TEST(CameraIntrinsicsFileTest, WrongMatrixSizes) {
  EXPECT_EQ(ErrorOf(Replace(kRosYaml, "[1000.5, 0, 640.25, 0, 999.5, 358.75, 0, 0, 1]",
                            "[1000.5, 0, 640.25, 0, 999.5, 358.75, 0, 0]")),
            "cal.yaml: camera_matrix.data: 8 numbers for a 3 x 3 matrix");
  EXPECT_EQ(ErrorOf(Replace(Replace(kRosYaml, "cols: 3", "cols: 4"),
                            "[1000.5, 0, 640.25, 0, 999.5, 358.75, 0, 0, 1]",
                            "[1000.5, 0, 640.25, 0, 0, 999.5, 358.75, 0, 0, 0, 1, 0]")),
            "cal.yaml: camera_matrix: must be 3 x 3, got 3 x 4");
  EXPECT_EQ(ErrorOf(Replace(Replace(kRosYaml, "cols: 5", "cols: 6"), "-0.025]", "-0.025, 0]")),
            "cal.yaml: distortion_coefficients: 6 coefficients; the pinhole takes 0, 4, 5, 8, "
            "12 or 14 (k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]])");
  EXPECT_EQ(ErrorOf(Replace(kRosYaml, "[1000.5, 0, 640.25,", "[1000.5, 0.5, 640.25,")),
            "cal.yaml: camera_matrix: skew 0.5: linecal's camera models have none");
}

TEST(CameraIntrinsicsFileTest, UnknownModelsAreNamed) {
  EXPECT_EQ(ErrorOf(Replace(kRosYaml, "plumb_bob", "mei")),
            "cal.yaml: distortion_model: 'mei' is not plumb_bob, rational_polynomial, radtan "
            "(pinhole), equidistant, fisheye or kannala_brandt (fisheye)");
  EXPECT_EQ(
      ErrorOf(Replace(kKalibrYaml, "distortion_model: radtan", "distortion_model: fov"), "cam0"),
      "cal.yaml: cam0.distortion_model: 'fov' is not radtan, equidistant or none");
}

TEST(CameraIntrinsicsFileTest, BadNumbersAreNamed) {
  EXPECT_EQ(ErrorOf(Replace(kRosYaml, "0.0001, -0.0002", "0.0001, x2")),
            "cal.yaml: distortion_coefficients.data[3]: 'x2' is not a finite number");
  EXPECT_EQ(ErrorOf(Replace(kRosYaml, "999.5, 358.75", ".nan, 358.75")),
            "cal.yaml: camera_matrix.data[4]: '.nan' is not a finite number");
  EXPECT_EQ(ErrorOf(Replace(kOpenCvYaml, "image_width: 1280", "image_width: 1280.5")),
            "cal.yaml: image_width: '1280.5' is not a whole number");
  EXPECT_EQ(ErrorOf(Replace(kOpenCvYaml, "image_width: 1280", "image_width: 0")),
            "cal.yaml: image_width: must be within 1..16384, got 0");
  EXPECT_EQ(ErrorOf(Replace(kKalibrYaml, "[1280, 720]", "[1280, 720.5]"), "cam0"),
            "cal.yaml: cam0.resolution: 720.5 is not a side of 1..16384 px");
  // Numbers that parse but make no camera: CameraIntrinsics::Validate's message, after the file.
  const std::string negative = ErrorOf(Replace(kRosYaml, "[1000.5, 0,", "[-1000.5, 0,"));
  EXPECT_EQ(negative.rfind("cal.yaml: fx = -1000.5", 0), 0u) << negative;
}

TEST(CameraIntrinsicsFileTest, FileErrorsNameTheFile) {
  const std::string missing = ::testing::TempDir() + "/no_such_intrinsics.yaml";
  const absl::StatusOr<CameraIntrinsics> none = ReadCameraIntrinsicsFile(missing, "");
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.status().message().find(missing), std::string::npos) << none.status();
  EXPECT_EQ(ErrorOf("camera_matrix: [1, 2"),
            "cal.yaml: not YAML or JSON (line 1: end of sequence flow not found)");
  EXPECT_EQ(ErrorOf("- 1\n- 2\n"), "cal.yaml: not a map");
  // A file on disk reads as its text does.
  const std::string path =
      ::testing::TempDir() + "/intrinsics_" + std::to_string(::getpid()) + ".yaml";
  std::ofstream(path) << kOpenCvYaml;
  const absl::StatusOr<CameraIntrinsics> in = ReadCameraIntrinsicsFile(path, "");
  std::filesystem::remove(path);
  ASSERT_TRUE(in.ok()) << in.status();
  ExpectFrontCamera(*in, true);
}

}  // namespace
}  // namespace linecal
