// Orbit cameras for the reference raycaster, in Blender's conventions (Z up): the camera, the
// named views, placing a camera around a box, and stereo pairs.
#pragma once

#include <openvdb/Types.h>
#include <openvdb/math/Ray.h>

#include <optional>
#include <string>
#include <utility>

namespace lic {

enum class Projection { Perspective, Orthographic };
const char* toString(Projection);

/// A camera in world space. `right`, `up` and `forward` are unit and orthogonal, with
/// right × up = −forward (a right-handed frame looking down its own −Z, as Blender's camera).
/// The image has `width` × `height` square pixels; pixel (0, 0) is the top-left one, rows go
/// down, and the ray of pixel (i, j) passes through its centre (i + ½, j + ½).
struct Camera
{
    Projection projection = Projection::Perspective;
    openvdb::Vec3d position{0.0, -1.0, 0.0}; ///< world units
    openvdb::Vec3d forward{0.0, 1.0, 0.0};   ///< viewing direction
    openvdb::Vec3d up{0.0, 0.0, 1.0};        ///< image up
    openvdb::Vec3d right{1.0, 0.0, 0.0};     ///< image right
    openvdb::Vec3d target{0.0, 0.0, 0.0};    ///< the orbit centre (world bbox centre)
    double fovY = 30.0;        ///< perspective: full vertical field of view, degrees
    double orthoWidth = 1.0;   ///< orthographic: width of the view, world units
    double orthoHeight = 1.0;  ///< orthographic: height of the view, world units
    int width = 512;           ///< pixels
    int height = 512;          ///< pixels
    double azimuth = 0.0;      ///< degrees, as set up by makeCamera (informational)
    double elevation = 0.0;    ///< degrees, as set up by makeCamera (informational)
    double distance = 1.0;     ///< |position − target|, world units

    /// Full horizontal field of view in degrees (perspective).
    double fovX() const;
    /// The world ray through continuous pixel coordinates (x, y) (pixel centres at +½):
    /// unit direction; perspective rays start at `position`, orthographic ones on the image
    /// plane through `position`.
    openvdb::math::Ray<double> ray(double x, double y) const;
};

/// Named views, Blender's numpad views with Z up: front looks along +Y (camera on −Y), back
/// along −Y, right along −X (camera on +X), left along +X, top down −Z (X right, Y up in the
/// image), bottom up +Z (X right, −Y up in the image).
enum class View { Front, Back, Left, Right, Top, Bottom };
/// @throw lic::InputError for names other than front, back, left, right, top, bottom.
View viewFromString(const std::string&);
const char* toString(View);
/// The (azimuth, elevation) in degrees of a named view (see CameraSettings).
std::pair<double, double> viewAngles(View);

/// How to place an orbit camera around a world box.
///
/// Azimuth A and elevation E (degrees) put the camera in direction
/// d = (sin A cos E, −cos A cos E, sin E) from the box centre, looking back at it: A = 0 is the
/// front view (camera on −Y), A = 90 the right view (camera on +X), E = 90 the top view.
/// Image right is (cos A, sin A, 0) and image up = right × forward, so Z is up whenever |E| < 90.
struct CameraSettings
{
    double azimuth = 0.0;   ///< degrees
    double elevation = 0.0; ///< degrees, in [−90, 90]
    /// World units from the box centre to the camera; unset: perspective is placed at the
    /// smallest distance that fits the box's 8 corners in the frame (less `margin`),
    /// orthographic at 2 × the box's bounding-sphere radius (any distance outside the box
    /// renders the same).
    std::optional<double> distance;
    double fovY = 30.0;          ///< perspective: vertical field of view, degrees, in (0, 180)
    bool orthographic = false;
    /// Orthographic: the view's height in world units; unset: fit the box (less `margin`).
    std::optional<double> orthoHeight;
    int width = 1024;            ///< pixels, ≥ 1
    int height = 1024;           ///< pixels, ≥ 1
    double margin = 0.04;        ///< fraction of the half-frame left empty around the fitted box

    /// @throw lic::InputError naming the first out-of-range value.
    void validate() const;
};

/// @brief An orbit camera framing world box `box` (normally the active voxels' world bbox).
/// @throw lic::InputError for bad settings (see CameraSettings::validate) or an empty box. A
///        camera inside the box is allowed (rays then start at the camera).
Camera makeCamera(const CameraSettings& settings, const openvdb::BBoxd& box);

/// @brief The left and right eyes of a stereo pair around `centre`: the camera orbited about
///        the target, around its `up` axis, by ∓atan(eyeSeparation / 2 / distance), so both
///        eyes converge on the target (zero parallax there). Works for both projections.
/// @param eyeSeparation world units between the eyes (> 0)
std::pair<Camera, Camera> stereoPair(const Camera& centre, double eyeSeparation);

} // namespace lic
