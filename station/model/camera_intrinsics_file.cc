#include "station/model/camera_intrinsics_file.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "detectors/core/image_view.h"
#include "station/io/json_reader.h"
#include "station/model/car_model.h"

namespace linecal {
namespace {

// A node of the parsed file with its path from the root, so that every error names the file
// and the key ("cal.yaml: camera_matrix.data[2]: 'x' is not a number").
class YamlField {
 public:
  YamlField(YAML::Node node, const std::string* source, std::string path)
      : node_(std::move(node)), source_(source), path_(std::move(path)) {}

  const YAML::Node& node() const { return node_; }
  const std::string& source() const { return *source_; }

  absl::Status Error(const std::string& what) const {
    return absl::InvalidArgumentError(absl::StrCat(*source_, ": ", path_, ": ", what));
  }

  bool Has(const std::string& key) const { return node_.IsMap() && node_[key]; }

  YamlField At(const std::string& key) const {
    return YamlField(node_[key], source_, path_.empty() ? key : absl::StrCat(path_, ".", key));
  }

  // The child `key`, or "<path>.key: missing".
  absl::StatusOr<YamlField> Child(const std::string& key) const {
    if (!node_.IsMap()) return Error("not a map");
    YamlField child = At(key);
    if (!child.node_) return child.Error("missing");
    return child;
  }

  absl::StatusOr<double> Number() const {
    if (!node_.IsScalar()) return Error("not a number");
    double value = 0.0;
    if (!YAML::convert<double>::decode(node_, value) || !std::isfinite(value)) {
      return Error(absl::StrCat("'", node_.Scalar().substr(0, 32), "' is not a finite number"));
    }
    return value;
  }

  absl::StatusOr<std::int64_t> Integer() const {
    long long value = 0;
    if (!node_.IsScalar() || !YAML::convert<long long>::decode(node_, value)) {
      return Error(absl::StrCat("'", node_.IsScalar() ? node_.Scalar().substr(0, 32) : "",
                                "' is not a whole number"));
    }
    return value;
  }

  absl::StatusOr<std::string> String() const {
    if (!node_.IsScalar()) return Error("not a string");
    return node_.Scalar();
  }

  // A sequence of finite numbers, each error naming its index.
  absl::StatusOr<std::vector<double>> Numbers() const {
    if (!node_.IsSequence()) return Error("not a list of numbers");
    std::vector<double> values;
    for (std::size_t i = 0; i < node_.size(); ++i) {
      const YamlField element(node_[i], source_, absl::StrCat(path_, "[", i, "]"));
      absl::StatusOr<double> v = element.Number();
      if (!v.ok()) return v.status();
      values.push_back(*v);
    }
    return values;
  }

 private:
  YAML::Node node_;
  const std::string* source_;
  std::string path_;
};

// The image size keys of OpenCV and ROS files, 1..kMaxImageSide.
absl::StatusOr<int> ImageSide(const YamlField& root, const std::string& key) {
  absl::StatusOr<YamlField> f = root.Child(key);
  if (!f.ok()) return f.status();
  absl::StatusOr<std::int64_t> v = f->Integer();
  if (!v.ok()) return v.status();
  if (*v < 1 || *v > kMaxImageSide) {
    return f->Error(absl::StrCat("must be within 1..", kMaxImageSide, ", got ", *v));
  }
  return static_cast<int>(*v);
}

// An OpenCV matrix (`!!opencv-matrix` in YAML, `"type_id": "opencv-matrix"` in JSON) or a ROS
// matrix: a map of rows, cols and data (row-major); dt, OpenCV's element type, is not needed
// since the numbers are read as doubles. Its data, checked to hold rows * cols numbers.
absl::StatusOr<std::vector<double>> MatrixData(const YamlField& matrix, int* rows, int* cols) {
  for (const auto& [key, slot] : {std::pair{"rows", rows}, std::pair{"cols", cols}}) {
    absl::StatusOr<YamlField> f = matrix.Child(key);
    if (!f.ok()) return f.status();
    absl::StatusOr<std::int64_t> v = f->Integer();
    if (!v.ok()) return v.status();
    // No camera file holds a matrix larger than 14 (OpenCV's longest distortion vector).
    if (*v < 0 || *v > 16) return f->Error(absl::StrCat("must be within 0..16, got ", *v));
    *slot = static_cast<int>(*v);
  }
  absl::StatusOr<YamlField> data = matrix.Child("data");
  if (!data.ok()) return data.status();
  absl::StatusOr<std::vector<double>> values = data->Numbers();
  if (!values.ok()) return values.status();
  if (values->size() != static_cast<std::size_t>(*rows * *cols)) {
    return data->Error(
        absl::StrCat(values->size(), " numbers for a ", *rows, " x ", *cols, " matrix"));
  }
  return values;
}

std::optional<CameraModelType> ModelOfDistortion(const std::string& name) {
  for (const char* pinhole : {"plumb_bob", "rational_polynomial", "radtan"}) {
    if (name == pinhole) return CameraModelType::kPinhole;
  }
  for (const char* fisheye : {"equidistant", "fisheye", "kannala_brandt"}) {
    if (name == fisheye) return CameraModelType::kFisheye;
  }
  return std::nullopt;
}

// Sets the distortion of `in` (whose type is set) from a coefficient vector in OpenCV's
// order; `field` names the vector in errors.
absl::Status SetDistortion(const YamlField& field, const std::vector<double>& d,
                           CameraIntrinsics* in) {
  const std::size_t n = d.size();
  if (in->type == CameraModelType::kFisheye) {
    if (n != 4) {
      return field.Error(absl::StrCat(n, " coefficients; the fisheye takes 4 (k1 k2 k3 k4)"));
    }
    in->k1 = d[0];
    in->k2 = d[1];
    in->k3 = d[2];
    in->k4 = d[3];
    return absl::OkStatus();
  }
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14) {
    return field.Error(absl::StrCat(n,
                                    " coefficients; the pinhole takes 0, 4, 5, 8, 12 or 14 "
                                    "(k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]])"));
  }
  // OpenCV's names of the terms after k3, which linecal's pinhole does not have.
  static constexpr const char* kExtraTerms[] = {"k4", "k5", "k6", "s1", "s2",
                                                "s3", "s4", "tx", "ty"};
  for (std::size_t i = 5; i < n; ++i) {
    if (d[i] != 0.0) {
      return field.Error(absl::StrCat(kExtraTerms[i - 5], " = ", d[i],
                                      ": linecal's pinhole has no rational, thin-prism or tilt "
                                      "terms (k1 k2 p1 p2 k3 only)"));
    }
  }
  if (n == 0) return absl::OkStatus();
  in->k1 = d[0];
  in->k2 = d[1];
  in->p1 = d[2];
  in->p2 = d[3];
  if (n >= 5) in->k3 = d[4];
  return absl::OkStatus();
}

// CameraIntrinsics::Validate with the file (and camera) in front of its message.
absl::StatusOr<CameraIntrinsics> Validated(const CameraIntrinsics& in, const std::string& where) {
  if (absl::Status s = in.Validate(); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": ", s.message()));
  }
  return in;
}

absl::Status PickError(const std::string& source, const std::string& camera_name,
                       const std::vector<std::string>& names) {
  const std::string list = absl::StrJoin(names, ", ");
  if (camera_name.empty()) {
    return absl::InvalidArgumentError(
        names.empty()
            ? absl::StrCat(source, ": holds no camera")
            : absl::StrCat(source, ": holds several cameras (", list, "): name one of them"));
  }
  return absl::InvalidArgumentError(
      absl::StrCat(source, ": no camera '", camera_name, "' (cameras: ", list, ")"));
}

// `camera_name`, or the only name when it is empty; nullopt when neither (PickError says why).
std::optional<std::string> Pick(const std::string& camera_name,
                                const std::vector<std::string>& names) {
  if (camera_name.empty()) {
    return names.size() == 1 ? std::optional(names[0]) : std::nullopt;
  }
  for (const std::string& n : names) {
    if (n == camera_name) return n;
  }
  return std::nullopt;
}

absl::StatusOr<CameraIntrinsics> FromCarModel(const std::string& text, const std::string& source,
                                              const std::string& camera_name) {
  absl::StatusOr<CarModel> car = ParseCarModel(text, source);
  if (!car.ok()) return car.status();
  std::vector<std::string> names;
  for (const SensorModel& s : car->sensors) {
    if (s.kind == SensorKind::kCamera && s.intrinsics.has_value()) names.push_back(s.name);
  }
  const std::optional<std::string> name = Pick(camera_name, names);
  if (!name.has_value()) return PickError(source, camera_name, names);
  // ParseCarModel validated the intrinsics of every camera.
  return *car->FindSensor(*name)->intrinsics;
}

// OpenCV's cv::FileStorage files and ROS camera_info files, which share their keys.
absl::StatusOr<CameraIntrinsics> FromCameraMatrixFile(const YamlField& root,
                                                      const std::string& camera_name) {
  if (!camera_name.empty()) {
    if (!root.Has("camera_name")) {
      return absl::InvalidArgumentError(absl::StrCat(
          root.source(), ": holds one camera without a name, not '", camera_name, "'"));
    }
    absl::StatusOr<std::string> name = root.At("camera_name").String();
    if (!name.ok()) return name.status();
    if (*name != camera_name) {
      return root.At("camera_name").Error(absl::StrCat("'", *name, "', not '", camera_name, "'"));
    }
  }
  CameraIntrinsics in;
  if (root.Has("distortion_model")) {
    absl::StatusOr<std::string> model = root.At("distortion_model").String();
    if (!model.ok()) return model.status();
    const std::optional<CameraModelType> type = ModelOfDistortion(*model);
    if (!type.has_value()) {
      return root.At("distortion_model")
          .Error(absl::StrCat("'", model->substr(0, 32),
                              "' is not plumb_bob, rational_polynomial, radtan (pinhole), "
                              "equidistant, fisheye or kannala_brandt (fisheye)"));
    }
    in.type = *type;
  }
  // OpenCV's camera calibration tutorial (camera_calibration.cpp) writes fisheye_model 0 or 1
  // for cv::calibrateCamera or cv::fisheye::calibrate.
  if (root.Has("fisheye_model")) {
    const YamlField flag = root.At("fisheye_model");
    absl::StatusOr<std::int64_t> v = flag.Integer();
    if (!v.ok()) return v.status();
    if (*v != 0 && *v != 1) return flag.Error(absl::StrCat("must be 0 or 1, got ", *v));
    const CameraModelType type = *v == 1 ? CameraModelType::kFisheye : CameraModelType::kPinhole;
    if (root.Has("distortion_model") && type != in.type) {
      return flag.Error(
          absl::StrCat(*v, " contradicts distortion_model, a ", CameraModelTypeName(in.type)));
    }
    in.type = type;
  }
  absl::StatusOr<int> width = ImageSide(root, "image_width");
  if (!width.ok()) return width.status();
  absl::StatusOr<int> height = ImageSide(root, "image_height");
  if (!height.ok()) return height.status();
  in.width = *width;
  in.height = *height;

  absl::StatusOr<YamlField> k_field = root.Child("camera_matrix");
  if (!k_field.ok()) return k_field.status();
  int rows = 0;
  int cols = 0;
  absl::StatusOr<std::vector<double>> k = MatrixData(*k_field, &rows, &cols);
  if (!k.ok()) return k.status();
  if (rows != 3 || cols != 3) {
    return k_field->Error(absl::StrCat("must be 3 x 3, got ", rows, " x ", cols));
  }
  const std::vector<double>& m = *k;
  if (m[1] != 0.0) {
    return k_field->Error(absl::StrCat("skew ", m[1], ": linecal's camera models have none"));
  }
  if (m[3] != 0.0 || m[6] != 0.0 || m[7] != 0.0 || m[8] != 1.0) {
    return k_field->Error("not a camera matrix [fx 0 cx; 0 fy cy; 0 0 1]");
  }
  in.fx = m[0];
  in.cx = m[2];
  in.fy = m[4];
  in.cy = m[5];

  absl::StatusOr<YamlField> d_field = root.Child("distortion_coefficients");
  if (!d_field.ok()) return d_field.status();
  absl::StatusOr<std::vector<double>> d = MatrixData(*d_field, &rows, &cols);
  if (!d.ok()) return d.status();
  if (rows > 1 && cols > 1) {
    return d_field->Error(absl::StrCat("must be a vector, got ", rows, " x ", cols));
  }
  if (absl::Status s = SetDistortion(*d_field, *d, &in); !s.ok()) return s;
  return Validated(in, root.source());
}

// Kalibr's camchain: cam0, cam1, ...
absl::StatusOr<CameraIntrinsics> FromKalibr(const YamlField& root,
                                            const std::vector<std::string>& cameras,
                                            const std::string& camera_name) {
  const std::optional<std::string> name = Pick(camera_name, cameras);
  if (!name.has_value()) return PickError(root.source(), camera_name, cameras);
  const YamlField cam = root.At(*name);

  absl::StatusOr<YamlField> model_field = cam.Child("camera_model");
  if (!model_field.ok()) return model_field.status();
  absl::StatusOr<std::string> model = model_field->String();
  if (!model.ok()) return model.status();
  if (*model != "pinhole") {
    return model_field->Error(absl::StrCat("'", model->substr(0, 32),
                                           "' is not supported: linecal takes Kalibr's "
                                           "pinhole cameras (radtan, equidistant or none)"));
  }
  absl::StatusOr<YamlField> dm_field = cam.Child("distortion_model");
  if (!dm_field.ok()) return dm_field.status();
  absl::StatusOr<std::string> dm = dm_field->String();
  if (!dm.ok()) return dm.status();
  CameraIntrinsics in;
  if (*dm == "radtan" || *dm == "none") {
    in.type = CameraModelType::kPinhole;
  } else if (*dm == "equidistant") {
    in.type = CameraModelType::kFisheye;
  } else {
    return dm_field->Error(
        absl::StrCat("'", dm->substr(0, 32), "' is not radtan, equidistant or none"));
  }

  absl::StatusOr<YamlField> k_field = cam.Child("intrinsics");
  if (!k_field.ok()) return k_field.status();
  absl::StatusOr<std::vector<double>> k = k_field->Numbers();
  if (!k.ok()) return k.status();
  if (k->size() != 4) {
    return k_field->Error(absl::StrCat(k->size(), " numbers; a pinhole has 4 (fu fv pu pv)"));
  }
  in.fx = (*k)[0];
  in.fy = (*k)[1];
  in.cx = (*k)[2];
  in.cy = (*k)[3];

  absl::StatusOr<YamlField> r_field = cam.Child("resolution");
  if (!r_field.ok()) return r_field.status();
  absl::StatusOr<std::vector<double>> r = r_field->Numbers();
  if (!r.ok()) return r.status();
  if (r->size() != 2) return r_field->Error(absl::StrCat(r->size(), " numbers, not 2 (w h)"));
  for (int i = 0; i < 2; ++i) {
    const double side = (*r)[i];
    if (side != std::floor(side) || side < 1 || side > kMaxImageSide) {
      return r_field->Error(absl::StrCat(side, " is not a side of 1..", kMaxImageSide, " px"));
    }
  }
  in.width = static_cast<int>((*r)[0]);
  in.height = static_cast<int>((*r)[1]);

  // Kalibr writes no coefficients for distortion_model none.
  std::vector<double> coefficients;
  const YamlField d_field = cam.At("distortion_coeffs");
  if (d_field.node() || *dm != "none") {
    absl::StatusOr<YamlField> present = cam.Child("distortion_coeffs");
    if (!present.ok()) return present.status();
    absl::StatusOr<std::vector<double>> d = present->Numbers();
    if (!d.ok()) return d.status();
    coefficients = *d;
  }
  // radtan's k1 k2 r1 r2 are OpenCV's k1 k2 p1 p2.
  if (*dm == "radtan" && coefficients.size() != 4) {
    return d_field.Error(absl::StrCat(coefficients.size(),
                                      " coefficients; radtan has 4 "
                                      "(k1 k2 r1 r2)"));
  }
  if (*dm == "none" && !coefficients.empty()) {
    return d_field.Error(absl::StrCat(coefficients.size(), " coefficients for model none"));
  }
  if (absl::Status s = SetDistortion(d_field, coefficients, &in); !s.ok()) return s;
  return Validated(in, absl::StrCat(root.source(), ": ", *name));
}

bool IsKalibrCameraKey(const std::string& key) {
  if (key.size() < 4 || key.compare(0, 3, "cam") != 0) return false;
  for (std::size_t i = 3; i < key.size(); ++i) {
    if (key[i] < '0' || key[i] > '9') return false;
  }
  return true;
}

}  // namespace

absl::StatusOr<CameraIntrinsics> ParseCameraIntrinsics(const std::string& text,
                                                       const std::string& source,
                                                       const std::string& camera_name) {
  // yaml-cpp reports syntax errors and some conversions by exceptions: none leaves here.
  try {
    const YAML::Node node = YAML::Load(text);
    if (!node.IsMap()) return absl::InvalidArgumentError(absl::StrCat(source, ": not a map"));
    const YamlField root(node, &source, "");
    if (root.Has("sensors")) return FromCarModel(text, source, camera_name);
    std::vector<std::string> kalibr_cameras;
    for (const auto& entry : node) {
      const std::string key = entry.first.Scalar();
      if (IsKalibrCameraKey(key)) kalibr_cameras.push_back(key);
    }
    if (!kalibr_cameras.empty()) return FromKalibr(root, kalibr_cameras, camera_name);
    if (root.Has("camera_matrix")) return FromCameraMatrixFile(root, camera_name);
    return absl::InvalidArgumentError(
        absl::StrCat(source,
                     ": not a camera calibration: no camera_matrix (OpenCV, ROS), cam0 "
                     "(Kalibr) or sensors (linecal car model)"));
  } catch (const YAML::Exception& e) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": not YAML or JSON (line ", e.mark.line + 1, ": ", e.msg, ")"));
  }
}

absl::StatusOr<CameraIntrinsics> ReadCameraIntrinsicsFile(const std::string& path,
                                                          const std::string& camera_name) {
  absl::StatusOr<std::string> text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  return ParseCameraIntrinsics(*text, path, camera_name);
}

}  // namespace linecal
