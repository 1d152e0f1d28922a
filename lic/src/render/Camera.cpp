#include "lic/render/Camera.h"

#include "lic/util/Error.h"
#include "lic/util/Names.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

namespace lic {

namespace {

constexpr double kPi = 3.14159265358979323846;
double radians(double deg) { return deg * kPi / 180.0; }
double degrees(double rad) { return rad * 180.0 / kPi; }

/// sin and cos of an angle in degrees, exact at multiples of 90° (named views get exact axes).
double sinDeg(double deg)
{
    const double r = std::fmod(deg, 360.0);
    if (r == 0.0 || std::abs(r) == 180.0) return 0.0;
    if (r == 90.0 || r == -270.0) return 1.0;
    if (r == -90.0 || r == 270.0) return -1.0;
    return std::sin(radians(deg));
}
double cosDeg(double deg) { return sinDeg(deg + 90.0); }

std::string num(double v)
{
    std::ostringstream s;
    s << v;
    return s.str();
}

} // namespace

const char* toString(Projection p) { return p == Projection::Perspective ? "perspective" : "orthographic"; }

double Camera::fovX() const
{
    const double ty = std::tan(radians(fovY) * 0.5);
    return degrees(2.0 * std::atan(ty * double(width) / double(height)));
}

openvdb::math::Ray<double> Camera::ray(double x, double y) const
{
    const double u = 2.0 * x / double(width) - 1.0;  // −1 … 1, left → right
    const double v = 1.0 - 2.0 * y / double(height); // −1 … 1, bottom → top
    if (projection == Projection::Orthographic) {
        const openvdb::Vec3d o = position + right * (u * 0.5 * orthoWidth) + up * (v * 0.5 * orthoHeight);
        return openvdb::math::Ray<double>(o, forward);
    }
    const double ty = std::tan(radians(fovY) * 0.5);
    const double tx = ty * double(width) / double(height);
    openvdb::Vec3d d = forward + right * (u * tx) + up * (v * ty);
    d.normalize();
    return openvdb::math::Ray<double>(position, d);
}

namespace {
constexpr EnumName<View> kViewNames[] = {{View::Front, "front"}, {View::Back, "back"},   {View::Left, "left"},
                                         {View::Right, "right"}, {View::Top, "top"}, {View::Bottom, "bottom"}};
} // namespace

View viewFromString(const std::string& s) { return valueOf<View>(kViewNames, s, "view"); }

const char* toString(View v) { return nameOf<View>(kViewNames, v); }

std::pair<double, double> viewAngles(View v)
{
    switch (v) {
    case View::Front: return {0.0, 0.0};
    case View::Back: return {180.0, 0.0};
    case View::Right: return {90.0, 0.0};
    case View::Left: return {-90.0, 0.0};
    case View::Top: return {0.0, 90.0};
    case View::Bottom: return {0.0, -90.0};
    }
    return {0.0, 0.0};
}

void CameraSettings::validate() const
{
    if (!std::isfinite(azimuth)) throw InputError("azimuth " + num(azimuth) + " is not a number of degrees");
    if (!(elevation >= -90.0 && elevation <= 90.0))
        throw InputError("elevation " + num(elevation) + " is out of range; expected degrees in [-90, 90]");
    if (distance && !(*distance > 0.0 && std::isfinite(*distance)))
        throw InputError("distance " + num(*distance) + " is out of range; expected world units > 0");
    if (!(fovY > 0.0 && fovY < 180.0))
        throw InputError("field of view " + num(fovY) + " is out of range; expected degrees in (0, 180)");
    if (orthoHeight && !(*orthoHeight > 0.0 && std::isfinite(*orthoHeight)))
        throw InputError("orthographic height " + num(*orthoHeight) + " is out of range; expected world units > 0");
    if (width < 1 || height < 1 || width > 32768 || height > 32768)
        throw InputError("image size " + std::to_string(width) + "x" + std::to_string(height) +
                         " is out of range; expected 1 to 32768 pixels each way");
    if (!(margin >= 0.0 && margin < 0.5)) throw InputError("margin " + num(margin) + " is out of range; expected [0, 0.5)");
}

Camera makeCamera(const CameraSettings& s, const openvdb::BBoxd& box)
{
    s.validate();
    if (!box.isSorted() || !std::isfinite(box.min()[0]) || !std::isfinite(box.max()[0]))
        throw InputError("cannot frame an empty bounding box");
    Camera cam;
    cam.projection = s.orthographic ? Projection::Orthographic : Projection::Perspective;
    cam.width = s.width;
    cam.height = s.height;
    cam.fovY = s.fovY;
    cam.azimuth = s.azimuth;
    cam.elevation = s.elevation;
    cam.target = box.getCenter();

    const double sa = sinDeg(s.azimuth), ca = cosDeg(s.azimuth), se = sinDeg(s.elevation), ce = cosDeg(s.elevation);
    const openvdb::Vec3d d(sa * ce, -ca * ce, se); // towards the camera
    cam.forward = -d;
    cam.right = openvdb::Vec3d(ca, sa, 0.0);
    cam.up = cam.right.cross(cam.forward);
    cam.up.normalize();
    // Re-orthogonalise right against forward (exact up to rounding already).
    cam.right = cam.forward.cross(cam.up);
    cam.right.normalize();

    // Corners relative to the centre, in the camera frame.
    const double fill = 1.0 - s.margin;
    double maxX = 0, maxY = 0, radius = 0;
    std::vector<openvdb::Vec3d> rel;
    for (int c = 0; c < 8; ++c) {
        const openvdb::Vec3d p((c & 1) ? box.max()[0] : box.min()[0], (c & 2) ? box.max()[1] : box.min()[1],
                               (c & 4) ? box.max()[2] : box.min()[2]);
        const openvdb::Vec3d r = p - cam.target;
        rel.push_back(r);
        maxX = std::max(maxX, std::abs(r.dot(cam.right)));
        maxY = std::max(maxY, std::abs(r.dot(cam.up)));
        radius = std::max(radius, r.length());
    }
    radius = std::max(radius, 1e-12);
    const double aspect = double(s.width) / double(s.height);

    if (s.orthographic) {
        double h = s.orthoHeight ? *s.orthoHeight : std::max(2.0 * maxY, 2.0 * maxX / aspect) / fill;
        if (!(h > 0.0)) h = 2.0 * radius;
        cam.orthoHeight = h;
        cam.orthoWidth = h * aspect;
        cam.distance = s.distance ? *s.distance : 2.0 * radius;
    } else if (s.distance) {
        cam.distance = *s.distance;
    } else {
        const double ty = std::tan(radians(s.fovY) * 0.5) * fill;
        const double tx = ty * aspect;
        double dist = 0.0;
        for (const auto& r : rel) {
            const double depth = r.dot(d); // towards the camera
            dist = std::max(dist, depth + std::abs(r.dot(cam.right)) / tx);
            dist = std::max(dist, depth + std::abs(r.dot(cam.up)) / ty);
        }
        cam.distance = std::max(dist, 1e-9);
    }
    cam.position = cam.target + d * cam.distance;
    return cam;
}

std::pair<Camera, Camera> stereoPair(const Camera& centre, double eyeSeparation)
{
    if (!(eyeSeparation > 0.0 && std::isfinite(eyeSeparation)))
        throw InputError("eye separation " + num(eyeSeparation) + " is out of range; expected world units > 0");
    const double half = std::atan(0.5 * eyeSeparation / centre.distance);
    auto orbit = [&](double angle) {
        // Rotate position and frame about the axis `up` through the target (Rodrigues).
        const openvdb::Vec3d k = centre.up;
        auto rot = [&](const openvdb::Vec3d& v) {
            return v * std::cos(angle) + k.cross(v) * std::sin(angle) + k * (k.dot(v)) * (1.0 - std::cos(angle));
        };
        Camera c = centre;
        c.position = centre.target + rot(centre.position - centre.target);
        c.forward = rot(centre.forward);
        c.right = rot(centre.right);
        c.up = centre.up;
        return c;
    };
    // A rotation by +angle about `up` moves the camera towards +right (up × d = right): that is
    // the right eye.
    Camera right = orbit(half), left = orbit(-half);
    left.azimuth = right.azimuth = centre.azimuth;
    return {left, right};
}

} // namespace lic
