#include "core/render/pinhole_camera.h"

#include <array>
#include <charconv>
#include <cmath>
#include <numbers>
#include <string>

namespace outcore {

namespace {

// Below this sine of the angle between up and the view direction the
// camera's x axis (their cross product) is mostly rounding error.
constexpr double kMinUpSine = 1e-6;

std::string format_number(double value) {
  char text[32];
  const auto result = std::to_chars(text, text + sizeof(text), value);
  return std::string(text, result.ptr);
}

std::string format_vec3(const Vec3d& v) {
  return format_number(v.x) + "," + format_number(v.y) + "," + format_number(v.z);
}

bool finite(const Vec3d& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// Open3D's sums of three products come from Eigen's unrolled reductions,
// which add a0 + (a1 + a2); in float that order decides the last bit.
template <class T>
T sum3(T a0, T a1, T a2) {
  return a0 + (a1 + a2);
}

template <class T>
T norm(const Vec3<T>& v) {
  return std::sqrt(sum3(v.x * v.x, v.y * v.y, v.z * v.z));
}

Status check_scalars(const PinholeCamera& camera) {
  if (camera.width == 0 || camera.height == 0 || camera.width > kMaxImageSide ||
      camera.height > kMaxImageSide) {
    return invalid_argument("--size " + std::to_string(camera.width) + "x" + std::to_string(camera.height) +
                            ": width and height must be 1 to " + std::to_string(kMaxImageSide) + " pixels");
  }
  if (!(camera.fov_deg > 0 && camera.fov_deg < 180)) {
    return invalid_argument("--fov " + format_number(camera.fov_deg) +
                            ": the horizontal field of view must be more than 0 and less than 180 degrees");
  }
  return Status::Ok();
}

Status check_vectors(const PinholeCamera& camera) {
  const std::pair<const char*, const Vec3d*> vectors[] = {
      {"--eye", &camera.eye}, {"--center", &camera.center}, {"--up", &camera.up}};
  for (const auto& [name, v] : vectors) {
    if (!finite(*v)) {
      return invalid_argument(std::string(name) + " " + format_vec3(*v) + ": every component must be finite");
    }
  }
  for (int i = 0; i < 3; ++i) {
    // Beyond it the engine treats the rays as invalid (misses): an all-black
    // picture with no explanation.
    if (std::abs(camera.eye[i]) > kLargestRayComponent) {
      return invalid_argument("--eye " + format_vec3(camera.eye) + ": components must be within +-" +
                              format_number(kLargestRayComponent) +
                              ", the largest coordinate the engine traces");
    }
  }
  const double view = norm(camera.center - camera.eye);
  if (view == 0) {
    return invalid_argument("--eye " + format_vec3(camera.eye) + " and --center " +
                            format_vec3(camera.center) +
                            " are the same point: the view direction is undefined");
  }
  if (!std::isfinite(view)) {
    return invalid_argument("--center " + format_vec3(camera.center) + " is too far from --eye " +
                            format_vec3(camera.eye) + " for the view direction to be computed");
  }
  const double up = norm(camera.up);
  if (up == 0 || !std::isfinite(up)) {
    return invalid_argument("--up " + format_vec3(camera.up) +
                            ": must be non-zero, with a length a double can hold");
  }
  const double sine = norm(cross(camera.up / up, (camera.center - camera.eye) / view));
  if (!(sine >= kMinUpSine)) {
    return invalid_argument("--up " + format_vec3(camera.up) +
                            " is parallel to the view direction (--center minus --eye, " +
                            format_vec3(camera.center - camera.eye) + "): the camera's roll is undefined");
  }
  return Status::Ok();
}

}  // namespace

Expected<PinholeRays> PinholeRays::make(const PinholeCamera& camera) {
  OUTCORE_RETURN_IF_ERROR(check_scalars(camera));
  OUTCORE_RETURN_IF_ERROR(check_vectors(camera));
  // Open3D's steps, in its order and precision (RaycastingScene.cpp, both
  // CreateRaysPinhole overloads): the extrinsic rotation's rows, the
  // intrinsics' inverse by cofactors, their product, then float.
  const double w = camera.width;
  const double h = camera.height;
  const double focal = 0.5 * w / std::tan(0.5 * (std::numbers::pi / 180) * camera.fov_deg);
  const double cx = 0.5 * w;
  const double cy = 0.5 * h;
  Vec3d row1 = camera.up / norm(camera.up);
  Vec3d row2 = camera.center - camera.eye;
  row2 = row2 / norm(row2);
  Vec3d row0 = cross(row1, row2);
  row0 = row0 / norm(row0);
  row1 = cross(row2, row0);
  const Vec3d rows[3] = {row0, row1, row2};

  // Translation t = -R * eye, camera centre C = -R^T * t (= eye up to rounding).
  Vec3d t;
  for (int i = 0; i < 3; ++i)
    t[i] = sum3(-rows[i].x * camera.eye.x, -rows[i].y * camera.eye.y, -rows[i].z * camera.eye.z);
  Vec3d centre;
  for (int i = 0; i < 3; ++i) centre[i] = sum3(-rows[0][i] * t[0], -rows[1][i] * t[1], -rows[2][i] * t[2]);

  // K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]; Eigen inverts a 3x3 by its
  // cofactors times 1 / det, which is not exactly 1 / f on the diagonal.
  const double inv_det = 1.0 / (focal * focal);
  const double inv_k[3][3] = {{focal * inv_det, 0, -(cx * focal) * inv_det},
                              {0, focal * inv_det, -(focal * cy) * inv_det},
                              {0, 0, (focal * focal) * inv_det}};
  PinholeRays out;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      // (R^T * K^-1)(i, j)
      out.m_[i][j] = static_cast<float>(
          sum3(rows[0][i] * inv_k[0][j], rows[1][i] * inv_k[1][j], rows[2][i] * inv_k[2][j]));
    }
  }
  out.origin_ = Vec3f(centre);
  out.width_ = camera.width;
  out.height_ = camera.height;

  // The directions are linear in (x, y): the corners bound every component.
  for (const auto& [x, y] : std::array<std::pair<uint32_t, uint32_t>, 4>{
           {{0, 0}, {out.width_ - 1, 0}, {0, out.height_ - 1}, {out.width_ - 1, out.height_ - 1}}}) {
    const Vec3f d = out.ray(x, y).direction;
    for (int i = 0; i < 3; ++i) {
      if (!(std::abs(d[i]) <= kLargestRayComponent)) {
        return invalid_argument("--fov " + format_number(camera.fov_deg) +
                                ": the camera's rays are not finite at this field of view");
      }
    }
  }
  return out;
}

Ray PinholeRays::ray(uint32_t x, uint32_t y) const {
  // x + 0.5f is exact for any side up to 2^23.
  const float px = static_cast<float>(x) + 0.5f;
  const float py = static_cast<float>(y) + 0.5f;
  Ray ray;
  ray.origin = origin_;
  for (int i = 0; i < 3; ++i) ray.direction[i] = sum3(m_[i][0] * px, m_[i][1] * py, m_[i][2]);
  return ray;
}

void PinholeRays::rows(uint32_t first_row, std::span<Ray> out) const {
  std::size_t k = 0;
  for (uint32_t y = first_row; k < out.size(); ++y) {
    for (uint32_t x = 0; x < width_; ++x) out[k++] = ray(x, y);
  }
}

}  // namespace outcore
