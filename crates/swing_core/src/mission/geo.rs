//! Local flat-Earth frame about a geodetic origin: latitude/longitude ↔ North/East.
//!
//! The azimuthal equidistant projection PX4 uses for its local position frame (its
//! `MapProjection`; Snyder, *Map Projections — A Working Manual*, USGS 1987, eq. 25-2 ff.):
//! with the origin (φ₀, λ₀), a point (φ, λ) at angular distance c from it,
//! cos c = sin φ₀ sin φ + cos φ₀ cos φ cos(λ − λ₀), and k = c / sin c,
//! ```text
//! North = R k (cos φ₀ sin φ − sin φ₀ cos φ cos(λ − λ₀)),   East = R k cos φ sin(λ − λ₀),
//! ```
//! and back, with ρ = √(N² + E²), c = ρ / R,
//! φ = asin(cos c sin φ₀ + N sin c cos φ₀ / ρ),
//! λ = λ₀ + atan2(E sin c, ρ cos φ₀ cos c − N sin φ₀ sin c).
//! Distances from the origin are exact along great circles; within a few kilometres the
//! frame agrees with PX4's to well below a millimetre, so a waypoint projected here lands
//! where PX4's estimator puts it.

use crate::config::{in_range, ConfigError};

/// Mean Earth radius of the projection (PX4's `CONSTANTS_RADIUS_OF_EARTH`) [m].
pub const EARTH_RADIUS: f64 = 6_371_000.0;

/// A geodetic point: latitude and longitude [deg], altitude above mean sea level [m].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GeoPoint {
    /// Latitude [deg], north positive.
    pub lat: f64,
    /// Longitude [deg], east positive.
    pub lon: f64,
    /// Altitude above mean sea level [m].
    pub alt: f64,
}

impl GeoPoint {
    /// Check the point is on the Earth (|lat| < 90°, |lon| ≤ 180°, altitude finite and
    /// within −500 m … 10 km).
    pub fn validate(&self) -> Result<(), ConfigError> {
        in_range("lat", self.lat, -89.999, 89.999)?;
        in_range("lon", self.lon, -180.0, 180.0)?;
        in_range("alt", self.alt, -500.0, 10_000.0)?;
        Ok(())
    }
}

/// The local North/East frame about a geodetic origin (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalProjection {
    lat0: f64,
    lon0: f64,
    sin_lat0: f64,
    cos_lat0: f64,
}

impl LocalProjection {
    /// The frame about latitude `lat0`, longitude `lon0` [deg].
    pub fn new(lat0: f64, lon0: f64) -> Self {
        let phi0 = lat0.to_radians();
        Self {
            lat0,
            lon0,
            sin_lat0: phi0.sin(),
            cos_lat0: phi0.cos(),
        }
    }

    /// The origin's latitude and longitude [deg].
    pub fn origin(&self) -> (f64, f64) {
        (self.lat0, self.lon0)
    }

    /// North and East [m] of the point at `lat`, `lon` [deg].
    pub fn project(&self, lat: f64, lon: f64) -> (f64, f64) {
        let phi = lat.to_radians();
        let (sin_phi, cos_phi) = phi.sin_cos();
        let dlon = (lon - self.lon0).to_radians();
        let (sin_dlon, cos_dlon) = dlon.sin_cos();
        let cos_c = (self.sin_lat0 * sin_phi + self.cos_lat0 * cos_phi * cos_dlon).clamp(-1.0, 1.0);
        let c = cos_c.acos();
        let k = if c.abs() > 1e-12 { c / c.sin() } else { 1.0 };
        let north =
            k * (self.cos_lat0 * sin_phi - self.sin_lat0 * cos_phi * cos_dlon) * EARTH_RADIUS;
        let east = k * cos_phi * sin_dlon * EARTH_RADIUS;
        (north, east)
    }

    /// Latitude and longitude [deg] of the point `north`, `east` [m] from the origin.
    pub fn reproject(&self, north: f64, east: f64) -> (f64, f64) {
        let rho = north.hypot(east);
        if rho < 1e-9 {
            return (self.lat0, self.lon0);
        }
        let c = rho / EARTH_RADIUS;
        let (sin_c, cos_c) = c.sin_cos();
        let lat = (cos_c * self.sin_lat0 + north * sin_c * self.cos_lat0 / rho)
            .clamp(-1.0, 1.0)
            .asin();
        let lon = self.lon0.to_radians()
            + (east * sin_c).atan2(rho * self.cos_lat0 * cos_c - north * self.sin_lat0 * sin_c);
        (lat.to_degrees(), wrap_deg(lon.to_degrees()))
    }
}

/// A longitude into (−180°, 180°].
fn wrap_deg(lon: f64) -> f64 {
    let mut x = (lon + 180.0).rem_euclid(360.0) - 180.0;
    if x == -180.0 {
        x = 180.0;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_degree_of_latitude_is_its_arc_and_round_trips() {
        let p = LocalProjection::new(47.397742, 8.545594);
        // Due north: the distance along the meridian is R·Δφ exactly.
        let (n, e) = p.project(47.397742 + 0.01, 8.545594);
        let arc = EARTH_RADIUS * 0.01f64.to_radians();
        assert!((n - arc).abs() < 1e-6 && e.abs() < 1e-9, "{n} {e} {arc}");
        // Due east at the origin's latitude: the great-circle distance, a hair under
        // R cos φ Δλ (the parallel is not a great circle).
        let (n, e) = p.project(47.397742, 8.545594 + 0.01);
        let parallel = EARTH_RADIUS * 47.397742f64.to_radians().cos() * 0.01f64.to_radians();
        assert!(e < parallel && parallel - e < 1e-3, "{e} {parallel}");
        assert!(
            n > 0.0 && n < 0.1,
            "the parallel bends north of the great circle: {n}"
        );
        for (dn, de) in [(120.0, -35.0), (-2500.0, 4000.0), (0.3, 0.0), (0.0, -70.0)] {
            let (lat, lon) = p.reproject(dn, de);
            let (n2, e2) = p.project(lat, lon);
            assert!(
                (n2 - dn).abs() < 1e-6 && (e2 - de).abs() < 1e-6,
                "{dn},{de} → {n2},{e2}"
            );
        }
    }

    #[test]
    fn distances_agree_with_the_haversine_great_circle() {
        let (lat0, lon0) = (-33.86, 151.2);
        let p = LocalProjection::new(lat0, lon0);
        let (lat, lon) = (-33.87, 151.23);
        let (n, e) = p.project(lat, lon);
        let (p1, p2) = (lat0.to_radians(), lat.to_radians());
        let dphi = p2 - p1;
        let dl = (lon - lon0).to_radians();
        let a = (dphi / 2.0).sin().powi(2) + p1.cos() * p2.cos() * (dl / 2.0).sin().powi(2);
        let d = 2.0 * EARTH_RADIUS * a.sqrt().asin();
        assert!((n.hypot(e) - d).abs() < 1e-6, "{} vs {d}", n.hypot(e));
    }

    #[test]
    fn longitudes_wrap_across_the_date_line() {
        let p = LocalProjection::new(0.0, 179.9999);
        let (lat, lon) = p.reproject(0.0, 50.0);
        assert!(lat.abs() < 1e-9 && lon < -179.0, "{lat} {lon}");
        let (n, e) = p.project(lat, lon);
        assert!((e - 50.0).abs() < 1e-6 && n.abs() < 1e-6);
    }
}
