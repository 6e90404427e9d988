//! Equations of motion of the multirotor with a suspended payload.
//!
//! Vehicle (thesis 3.11–3.24): 6-DOF rigid body, translation integrated in the inertial NED
//! frame (equivalent to the body-frame form 3.11), attitude as a scalar-first quaternion
//! (3.13), Euler's equation for the body rates (3.12), thrust and moments from the four motor
//! thrusts by the X mixer (3.18–3.19), first-order motors Ṫ = (T_sp − T)/τ (3.20), drag
//! ½ρ V_rel|V_rel| C_Q per body axis with wind (3.21–3.22) and gravity (3.24).
//!
//! Payload (section 3.5): a chain of point masses on rigid massless links hanging from the
//! vehicle CoM (1 link: the point-mass payload; 2 links: the elongated "dynamic" payload of
//! 4.6.9). Instead of the Euler-angle Lagrangian (3.25–3.35), which is singular at
//! φ = ±90° and awkward at hover, each link is a unit vector n_i on the sphere (Sreenath, Lee
//! & Kumar 2013): r_i = r_{i−1} + l_i n_i. With body 0 the vehicle, G_i the non-tension forces
//! on body i and T_i ≥ 0 the tension of link i,
//!
//!   m_0 a_0 = G_0 + T_1 n_1,        m_i a_i = G_i − T_i n_i + T_{i+1} n_{i+1},
//!
//! and the rigid-link constraints n_i·(a_i − a_{i−1}) = −l_i |ṅ_i|² give the tridiagonal
//! system
//!
//!   T_i (1/m_i + 1/m_{i−1}) − T_{i+1} (n_i·n_{i+1})/m_i − T_{i−1} (n_i·n_{i−1})/m_{i−1}
//!     = l_i |ṅ_i|² + n_i·G_i/m_i − n_i·G_{i−1}/m_{i−1}.
//!
//! Then n̈_i = (a_i − a_{i−1})/l_i. The cable force acts on the vehicle exactly (both ways).
//! Payload drag is ½ρ C_p |w − v_i|(w − v_i); joint friction (3.31–3.32) is the force
//! −(c/l_i) ṅ_i on body i with its reaction on body i−1 (a moment −c ω at the joint).

use nalgebra::{Matrix3, Quaternion, Vector3, Vector4};

use super::params::{PayloadParams, VehicleParams, GRAVITY};

/// Most links a payload chain can have.
pub const MAX_LINKS: usize = 2;

/// Full continuous state of vehicle + payload.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantState {
    /// Vehicle CoM position, NED [m].
    pub pos: Vector3<f64>,
    /// Vehicle CoM velocity, NED [m/s].
    pub vel: Vector3<f64>,
    /// Attitude, body FRD → NED, scalar first.
    pub att: Quaternion<f64>,
    /// Body angular rates (p, q, r) [rad/s].
    pub rate: Vector3<f64>,
    /// Thrust of motors 1–4 [N] (PX4 quad X order).
    pub thrust: Vector4<f64>,
    /// Unit vectors of the payload links, from upper to lower end.
    pub n: [Vector3<f64>; MAX_LINKS],
    /// Time derivatives of the link unit vectors [1/s].
    pub ndot: [Vector3<f64>; MAX_LINKS],
}

impl PlantState {
    /// Vehicle at rest at `pos`, level, motors at `thrust_each` [N], links at the given
    /// projected angles (North–Down, East–Down) [rad].
    pub fn at_rest(pos: Vector3<f64>, thrust_each: f64, swing_n: f64, swing_e: f64) -> Self {
        let n = unit_from_swing(swing_n, swing_e);
        Self {
            pos,
            vel: Vector3::zeros(),
            att: Quaternion::new(1.0, 0.0, 0.0, 0.0),
            rate: Vector3::zeros(),
            thrust: Vector4::repeat(thrust_each),
            n: [n, Vector3::new(0.0, 0.0, 1.0)],
            ndot: [Vector3::zeros(); MAX_LINKS],
        }
    }

    /// `self + h·d`, the RK4 stage combination.
    #[inline]
    pub fn add_scaled(&self, d: &PlantState, h: f64) -> PlantState {
        PlantState {
            pos: self.pos + d.pos * h,
            vel: self.vel + d.vel * h,
            att: self.att + d.att * h,
            rate: self.rate + d.rate * h,
            thrust: self.thrust + d.thrust * h,
            n: [self.n[0] + d.n[0] * h, self.n[1] + d.n[1] * h],
            ndot: [self.ndot[0] + d.ndot[0] * h, self.ndot[1] + d.ndot[1] * h],
        }
    }

    /// Project back onto the constraint manifold: unit quaternion, unit links, ṅ ⟂ n.
    /// RK4 keeps these to O(h⁵) per step; the projection stops the slow drift.
    pub fn project(&mut self, links: usize) {
        let qn = self.att.norm();
        self.att /= qn;
        for i in 0..links {
            let nn = self.n[i].norm();
            self.n[i] /= nn;
            let radial = self.n[i].dot(&self.ndot[i]);
            self.ndot[i] -= self.n[i] * radial;
        }
    }

    /// Body → NED rotation matrix of the (unit) attitude quaternion (transpose of eq. 3.14).
    #[inline]
    pub fn rotation(&self) -> Matrix3<f64> {
        rotation(&self.att)
    }

    /// Inertial velocity of payload mass `i` (0-based) [m/s].
    pub fn payload_velocity(&self, p: &PayloadParams, i: usize) -> Vector3<f64> {
        let lengths = [p.length, p.length2];
        let mut v = self.vel;
        for k in 0..=i {
            v += self.ndot[k] * lengths[k];
        }
        v
    }

    /// Inertial position of payload mass `i` (0-based) [m].
    pub fn payload_position(&self, p: &PayloadParams, i: usize) -> Vector3<f64> {
        let lengths = [p.length, p.length2];
        let mut r = self.pos;
        for k in 0..=i {
            r += self.n[k] * lengths[k];
        }
        r
    }
}

/// Unit vector of a link whose projected angles are `swing_n` (North–Down plane) and
/// `swing_e` (East–Down plane), hanging below the attachment.
pub fn unit_from_swing(swing_n: f64, swing_e: f64) -> Vector3<f64> {
    Vector3::new(swing_n.tan(), swing_e.tan(), 1.0).normalize()
}

/// Projected swing angles (North–Down, East–Down) of a link and their rates [rad, rad/s].
///
/// These are what a two-axis crossed-bail angle sensor reads, rotated into the inertial
/// frame: swing_n = atan2(n_N, n_D), swing_e = atan2(n_E, n_D) (README "Conventions"; the thesis's θ and,
/// to first order, φ).
pub fn swing_angles(n: &Vector3<f64>, ndot: &Vector3<f64>) -> [f64; 4] {
    let (x, y, z) = (n.x, n.y, n.z);
    let (dx, dy, dz) = (ndot.x, ndot.y, ndot.z);
    let rn = x * x + z * z;
    let re = y * y + z * z;
    [
        x.atan2(z),
        y.atan2(z),
        if rn > 0.0 {
            (dx * z - x * dz) / rn
        } else {
            0.0
        },
        if re > 0.0 {
            (dy * z - y * dz) / re
        } else {
            0.0
        },
    ]
}

/// Body → NED rotation matrix of a unit quaternion (scalar first).
#[inline]
pub fn rotation(q: &Quaternion<f64>) -> Matrix3<f64> {
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    Matrix3::new(
        w * w + x * x - y * y - z * z,
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        w * w - x * x + y * y - z * z,
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        w * w - x * x - y * y + z * z,
    )
}

/// The X-quad mixing of eq. 3.19: motor thrusts → (δ_T, δ_A, δ_E, δ_R).
#[inline]
pub fn mix(t: &Vector4<f64>) -> [f64; 4] {
    let s = std::f64::consts::FRAC_1_SQRT_2;
    [
        t[0] + t[1] + t[2] + t[3],
        s * (-t[0] + t[1] + t[2] - t[3]),
        s * (t[0] - t[1] + t[2] - t[3]),
        t[0] + t[1] - t[2] - t[3],
    ]
}

/// Parameters the derivative needs, flattened once per run for speed.
#[derive(Clone, Debug)]
pub struct Model {
    /// Vehicle parameters.
    pub vehicle: VehicleParams,
    /// Payload parameters.
    pub payload: PayloadParams,
    links: usize,
    inertia: Vector3<f64>,
    masses: [f64; MAX_LINKS + 1],
    lengths: [f64; MAX_LINKS],
    arms: [f64; 2],
    gravity: f64,
}

/// Inputs held constant over one integration step.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepInput {
    /// Thrust setpoints of motors 1–4 [N].
    pub thrust_sp: Vector4<f64>,
    /// Wind velocity, NED [m/s].
    pub wind: Vector3<f64>,
    /// Extra force on the vehicle, NED [N] (tests; e.g. a constant thrust with no motors).
    pub external_force: Vector3<f64>,
}

/// Switches for idealised experiments (energy tests); all `true` in normal use.
#[derive(Clone, Copy, Debug)]
pub struct Effects {
    /// Aerodynamic drag of vehicle and payload.
    pub drag: bool,
    /// Joint friction.
    pub friction: bool,
    /// Rotational dynamics and motor thrust (false: attitude frozen, motors ignored).
    pub rotors: bool,
}

impl Default for Effects {
    fn default() -> Self {
        Self {
            drag: true,
            friction: true,
            rotors: true,
        }
    }
}

impl Model {
    /// Flatten validated parameters.
    pub fn new(vehicle: VehicleParams, payload: PayloadParams) -> Self {
        let links = payload.links();
        let inertia = Vector3::from(vehicle.inertia);
        let masses = [vehicle.mass, payload.mass, payload.mass2];
        let lengths = [payload.length, payload.length2];
        let arms = vehicle.moment_arms();
        Self {
            arms,
            vehicle,
            payload,
            links,
            inertia,
            masses,
            lengths,
            gravity: GRAVITY,
        }
    }

    /// Replace the payload parameters (kind, mass, length …) in flight; the state's links
    /// are the caller's to set (see [`super::events`]).
    pub fn set_payload(&mut self, payload: PayloadParams) {
        self.links = payload.links();
        self.masses[1] = payload.mass;
        self.masses[2] = payload.mass2;
        self.lengths = [payload.length, payload.length2];
        self.payload = payload;
    }

    /// Set the (first) cable length [m] in flight.
    pub fn set_length(&mut self, length: f64) {
        self.payload.length = length;
        self.lengths[0] = length;
    }

    /// Set the vehicle mass [kg] in flight.
    pub fn set_vehicle_mass(&mut self, mass: f64) {
        self.vehicle.mass = mass;
        self.masses[0] = mass;
    }

    /// Number of payload links.
    pub fn links(&self) -> usize {
        self.links
    }

    /// Total mass of vehicle and payload [kg].
    pub fn total_mass(&self) -> f64 {
        self.vehicle.mass + self.payload.total_mass()
    }

    /// Time derivative of the state (the right-hand side integrated by RK4).
    pub fn derivative(&self, s: &PlantState, u: &StepInput, fx: Effects) -> PlantState {
        let v = &self.vehicle;
        let rho = v.air_density;
        let rot = rotation(&s.att);
        let e3 = Vector3::new(0.0, 0.0, 1.0);

        // Vehicle forces other than cable tension, NED.
        let mut g0 = e3 * (self.masses[0] * self.gravity) + u.external_force;
        let mut d_rate = Vector3::zeros();
        let mut d_att = Quaternion::new(0.0, 0.0, 0.0, 0.0);
        let mut d_thrust = Vector4::zeros();
        if fx.rotors {
            let [dt, da, de, dr] = mix(&s.thrust);
            g0 += rot * Vector3::new(0.0, 0.0, -dt);
            // δ_A, δ_E carry the square X's 1/√2; a rectangle's arms replace it.
            let [pitch_arm, roll_arm] = self.arms;
            let moment = Vector3::new(
                roll_arm * std::f64::consts::SQRT_2 * da,
                pitch_arm * std::f64::consts::SQRT_2 * de,
                v.yaw_arm * dr,
            );
            let iw = self.inertia.component_mul(&s.rate);
            d_rate = (moment - s.rate.cross(&iw)).component_div(&self.inertia);
            // q̇ = ½ q ⊗ (0, ω), eq. 3.13.
            d_att = s.att * Quaternion::new(0.0, s.rate.x, s.rate.y, s.rate.z) * 0.5;
            d_thrust = (u.thrust_sp - s.thrust) / v.motor_tau;
        }
        if fx.drag {
            let rel_body = rot.transpose() * (u.wind - s.vel);
            let f_body = Vector3::new(
                v.drag[0] * rel_body.x * rel_body.x.abs(),
                v.drag[1] * rel_body.y * rel_body.y.abs(),
                v.drag[2] * rel_body.z * rel_body.z.abs(),
            ) * (0.5 * rho);
            g0 += rot * f_body;
        }

        let nl = self.links;
        let mut out = PlantState {
            pos: s.vel,
            vel: Vector3::zeros(),
            att: d_att,
            rate: d_rate,
            thrust: d_thrust,
            n: s.ndot,
            ndot: [Vector3::zeros(); MAX_LINKS],
        };
        if nl == 0 {
            out.vel = g0 / self.masses[0];
            return out;
        }

        // Non-tension forces G_i on every body; friction pairs between neighbours.
        let p = &self.payload;
        let mut g = [g0, Vector3::zeros(), Vector3::zeros()];
        let mut vel_i = s.vel;
        for i in 0..nl {
            let m = self.masses[i + 1];
            vel_i += s.ndot[i] * self.lengths[i];
            let mut gi = e3 * (m * self.gravity);
            if fx.drag && p.drag > 0.0 {
                let rel = u.wind - vel_i;
                gi += rel * (0.5 * rho * p.drag * rel.norm());
            }
            if fx.friction && p.friction > 0.0 {
                let ff = s.ndot[i] * (-p.friction / self.lengths[i]);
                gi += ff;
                g[i] -= ff;
            }
            g[i + 1] += gi;
        }

        // Tensions from the constraint equations (tridiagonal, at most 2×2).
        let m = &self.masses;
        let n = &s.n;
        let rhs = |i: usize| -> f64 {
            self.lengths[i] * s.ndot[i].norm_squared() + n[i].dot(&g[i + 1]) / m[i + 1]
                - n[i].dot(&g[i]) / m[i]
        };
        let mut tension = [0.0; MAX_LINKS];
        if nl == 1 {
            tension[0] = rhs(0) / (1.0 / m[1] + 1.0 / m[0]);
        } else {
            let a11 = 1.0 / m[1] + 1.0 / m[0];
            let a12 = -n[0].dot(&n[1]) / m[1];
            let a21 = -n[1].dot(&n[0]) / m[1];
            let a22 = 1.0 / m[2] + 1.0 / m[1];
            let (b1, b2) = (rhs(0), rhs(1));
            let det = a11 * a22 - a12 * a21;
            tension[0] = (b1 * a22 - a12 * b2) / det;
            tension[1] = (a11 * b2 - a21 * b1) / det;
        }

        // Accelerations of every body, then link accelerations.
        let mut acc = [Vector3::zeros(); MAX_LINKS + 1];
        for i in 0..=nl {
            let mut f = g[i];
            if i >= 1 {
                f -= n[i - 1] * tension[i - 1];
            }
            if i < nl {
                f += n[i] * tension[i];
            }
            acc[i] = f / m[i];
        }
        out.vel = acc[0];
        for i in 0..nl {
            out.ndot[i] = (acc[i + 1] - acc[i]) / self.lengths[i];
        }
        out
    }

    /// One classical RK4 step of length `h` with inputs held, followed by the projection.
    pub fn rk4(&self, s: &PlantState, u: &StepInput, h: f64, fx: Effects) -> PlantState {
        let k1 = self.derivative(s, u, fx);
        self.rk4_from(s, &k1, u, h, fx)
    }

    /// [`Self::rk4`] with the first stage `k1` = `derivative(s, u, fx)` already evaluated
    /// (the simulator reads the vehicle's acceleration from it for the IMU).
    pub fn rk4_from(
        &self,
        s: &PlantState,
        k1: &PlantState,
        u: &StepInput,
        h: f64,
        fx: Effects,
    ) -> PlantState {
        let k2 = self.derivative(&s.add_scaled(k1, 0.5 * h), u, fx);
        let k3 = self.derivative(&s.add_scaled(&k2, 0.5 * h), u, fx);
        let k4 = self.derivative(&s.add_scaled(&k3, h), u, fx);
        let mut next = PlantState {
            pos: s.pos + (k1.pos + (k2.pos + k3.pos) * 2.0 + k4.pos) * (h / 6.0),
            vel: s.vel + (k1.vel + (k2.vel + k3.vel) * 2.0 + k4.vel) * (h / 6.0),
            att: s.att + (k1.att + (k2.att + k3.att) * 2.0 + k4.att) * (h / 6.0),
            rate: s.rate + (k1.rate + (k2.rate + k3.rate) * 2.0 + k4.rate) * (h / 6.0),
            thrust: s.thrust + (k1.thrust + (k2.thrust + k3.thrust) * 2.0 + k4.thrust) * (h / 6.0),
            n: [Vector3::zeros(); MAX_LINKS],
            ndot: [Vector3::zeros(); MAX_LINKS],
        };
        for i in 0..MAX_LINKS {
            next.n[i] = s.n[i] + (k1.n[i] + (k2.n[i] + k3.n[i]) * 2.0 + k4.n[i]) * (h / 6.0);
            next.ndot[i] =
                s.ndot[i] + (k1.ndot[i] + (k2.ndot[i] + k3.ndot[i]) * 2.0 + k4.ndot[i]) * (h / 6.0);
        }
        next.project(self.links);
        next
    }

    /// Total mechanical energy [J] with an extra constant external force `f_ext` on the
    /// vehicle counted as a potential (−f_ext·r); used by the conservation test.
    pub fn energy(&self, s: &PlantState, f_ext: &Vector3<f64>) -> f64 {
        let mut e = 0.5 * self.masses[0] * s.vel.norm_squared()
            - self.masses[0] * self.gravity * s.pos.z
            - f_ext.dot(&s.pos);
        for i in 0..self.links {
            let v = s.payload_velocity(&self.payload, i);
            let r = s.payload_position(&self.payload, i);
            e += 0.5 * self.masses[i + 1] * v.norm_squared()
                - self.masses[i + 1] * self.gravity * r.z;
        }
        // Rotational kinetic energy (zero when rotors are off and rates are zero).
        e += 0.5 * s.rate.dot(&self.inertia.component_mul(&s.rate));
        e
    }
}
