//! The unit tests of the benches' shared code (`benches/measured/`): the plans' syntax, the trust
//! matrix's z-values, cell figures and bars. Under `cargo bench` a `harness = false` bench is
//! compiled with `cfg(test)` but without its `#[test]`s and runs its `main`, so the tests live
//! here, on the same source.

// Only the tests below use it here.
#[allow(dead_code)]
#[path = "../benches/measured/mod.rs"]
mod measured;

mod replay {
    use crate::measured::replay::*;

    #[test]
    fn a_plan_without_seconds_runs_the_default_length() {
        assert_eq!(rates_and_duration("180,-180@300"), ("180,-180", "300"));
        assert_eq!(rates_and_duration("180,90"), ("180,90", DURATION_S));
        assert_eq!(full_plan("180,90"), format!("180,90@{DURATION_S}"));
        assert_eq!(full_plan("-180@20"), "-180@20");
    }

    /// A `/files` design keeps its suffix through `full_design` and is simulated one capture per
    /// pose and rate, each with a noise draw of its own (`capture_level`, at level 0 unless the
    /// case gives one); any other design is one capture.
    #[test]
    fn a_files_design_is_a_capture_per_pose_and_rate() {
        assert_eq!(full_design("180,90/files"), format!("180,90@{DURATION_S}/files"));
        assert_eq!(full_design("-180@20"), "-180@20");
        let g = vec!["--effect=g_sensitivity".to_string()];
        assert_eq!(capture_plans("180@20", &g), vec![(String::new(), "180@20".into(), g.clone())]);
        let plans = capture_plans("180,-90@20/files", &g);
        let names: Vec<(&str, &str)> = plans.iter().map(|(d, p, _)| (d.as_str(), p.as_str())).collect();
        assert_eq!(names, [("p1_180", "180@20"), ("p1_-90", "-90@20"), ("p2_180", "180@20"), ("p2_-90", "-90@20")]);
        assert_eq!(plans[3].2, ["--effect=g_sensitivity", "--effect=capture_level=0", "--poses=2"]);
        let level = vec!["--effect=capture_level=0.01".to_string()];
        assert_eq!(capture_plans("180@20/files", &level)[1].2, ["--effect=capture_level=0.01", "--poses=2"]);
    }

    #[test]
    fn a_nan_is_the_largest_of_all() {
        assert_eq!(max_abs(&[1.0, -3.0, 2.0]), 3.0);
        assert_eq!(max_abs(&[1.0, f64::NAN]), f64::INFINITY);
        assert_eq!(max_abs(&[]), 0.0);
    }
}

mod trust {
    use crate::measured::trust::*;
    use host::calib::result::truth_check::direction_z;
    use serde_json::{json, Value};

    const XYZ: [char; 3] = ['x', 'y', 'z'];

    /// The tool's own parameter names (no `m_xx`: check.py then takes 4i + j).
    fn tool_names() -> Vec<String> {
        (0..12)
            .map(|p| match p % 4 {
                3 => format!("offset_{}_counts", XYZ[p / 4]),
                j => format!("m_{}.omega_{}_dps", XYZ[p / 4], XYZ[j]),
            })
            .collect()
    }

    /// A hand-made truth (k = 100, 200, 300; x and y on their package axes, z tilted by
    /// asin 0.001 towards x) and a calibration whose every z is known by hand.
    fn pair() -> (Value, Value) {
        let cz = (1.0f64 - 1e-6).sqrt();
        let truth = json!({
            "k_counts_per_dps": [100.0, 200.0, 300.0],
            "s": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.001, 0.0, cz]],
            "m_counts_per_dps": [[100.0, 0.0, 0.0], [0.0, 200.0, 0.0], [0.3, 0.0, 300.0 * cz]],
        });
        let mut cov = vec![vec![0.0; 12]; 12];
        // Row x: σ 0.1 on every element (isotropic). Row y: σ 0.2. Row z: σ 0.15, 0.2, 0.01 with
        // cov(m_zx, m_zy) = 0.018.
        for (p, var) in
            [(0, 0.01), (1, 0.01), (2, 0.01), (4, 0.04), (5, 0.04), (6, 0.04), (8, 0.0225), (9, 0.04), (10, 1e-4)]
        {
            cov[p][p] = var;
        }
        cov[8][9] = 0.018;
        cov[9][8] = 0.018;
        for b in [3, 7, 11] {
            cov[b][b] = 1.0;
        }
        let cal = json!({
            "param_names": tool_names(),
            "cov": cov,
            "m_counts_per_dps": [[100.2, 0.3, 0.0], [0.0, 199.9, -0.4], [0.0, 0.0, 300.0]],
            "axes": [
                {"k_counts_per_dps": 100.25, "k_sigma": 0.05},
                {"k_counts_per_dps": 199.9, "k_sigma": 0.2},
                {"k_counts_per_dps": 300.3, "k_sigma": 0.1},
            ],
        });
        (cal, truth)
    }

    #[test]
    fn the_z_values_of_a_hand_made_pair() {
        let (cal, truth) = pair();
        let z = z_values(&cal, &truth).unwrap();
        // Per axis: k, m_i0, m_i1, m_i2, direction. With an isotropic σ on the row, the
        // direction's z is the row's component across the true axis over σ: 0.3/0.1, 0.4/0.2.
        // Row z lies on z, the truth 0.001 off it towards x: across-error 0.001·300 = 0.3 along
        // x, whose variance within the plane, after the y-x correlation is taken out, is
        // 0.0225 − 0.018²/0.04 = 0.0144: z = 0.3/0.12 = 2.5.
        let m_zz = 300.0 * (1.0 - (1.0f64 - 1e-6).sqrt()) / 0.01;
        let want = [5.0, 2.0, 3.0, 0.0, 3.0, 0.5, 0.0, 0.5, 2.0, 2.0, 3.0, 2.0, 0.0, m_zz, 2.5];
        for (i, (got, want)) in z.iter().zip(want).enumerate() {
            assert!((got - want).abs() < 1e-6, "z[{i}] = {got}, not {want}: {z:?}");
        }
    }

    #[test]
    fn named_m_parameters_are_found_wherever_they_are() {
        // check.py takes `m_<i><j>` from param_names when the name is there: swap m_xx and m_xy
        // in the names and in cov, and the z-values stay.
        let (mut cal, truth) = pair();
        let mut names: Vec<String> = tool_names();
        names[0] = "m_xy".into();
        names[1] = "m_xx".into();
        names[2] = "m_xz".into();
        cal["param_names"] = json!(names);
        let z0 = z_values(&pair().0, &truth).unwrap();
        let cov = cal["cov"].clone();
        let swap = |p: usize| [1, 0].get(p).copied().unwrap_or(p);
        cal["cov"] = json!((0..12)
            .map(|r| (0..12).map(|q| cov[swap(r)][swap(q)].clone()).collect::<Vec<_>>())
            .collect::<Vec<_>>());
        // Make the swap matter: m_xx and m_xy get different variances.
        cal["cov"][1][1] = json!(0.04);
        let z = z_values(&cal, &truth).unwrap();
        assert!((z[1] - 1.0).abs() < 1e-9, "m_xx against its own variance, at index 1: {}", z[1]);
        assert_eq!(z[2], z0[2], "m_xy against its variance, now at index 0");
    }

    #[test]
    fn a_covariance_flat_across_the_axis_makes_the_direction_infinite() {
        let cov3 = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        assert_eq!(direction_z([0.0, 0.0, 300.0], cov3, [0.0, 0.0, 1.0]), f64::INFINITY);
        let nan = [[f64::NAN; 3]; 3];
        assert_eq!(direction_z([0.0, 0.0, 300.0], nan, [0.0, 0.0, 1.0]), f64::INFINITY);
    }

    #[test]
    fn a_calibration_without_its_fields_is_an_error() {
        let (mut cal, truth) = pair();
        cal["axes"] = json!([]);
        assert!(z_values(&cal, &truth).is_err());
    }

    fn seed(code: i32, z: f64) -> SeedOutcome {
        SeedOutcome { code: Some(code), z: Some([z; Z_COUNT]), cpu_s: Some(0.5) }
    }

    #[test]
    fn z_rms_of_known_values() {
        assert_eq!(z_rms(&[[1.0; Z_COUNT]; 3]), 1.0);
        let mut a = [3.0; Z_COUNT];
        a[..Z_COUNT / 2].fill(-4.0);
        let b = [2.0; Z_COUNT];
        let lo = Z_COUNT / 2;
        let want =
            ((16.0 * lo as f64 + 9.0 * (Z_COUNT - lo) as f64 + 4.0 * Z_COUNT as f64) / (2 * Z_COUNT) as f64).sqrt();
        assert!((z_rms(&[a, b]) - want).abs() < 1e-12);
        let mut c = [1.0; Z_COUNT];
        c[3] = f64::NAN;
        assert_eq!(z_rms(&[c]), f64::INFINITY);
    }

    #[test]
    fn one_exit_0_at_z_5_makes_the_cell_confidently_wrong() {
        let c = cell_stats(&[seed(0, 1.0), seed(0, 5.0), seed(3, 9.0)]);
        assert_eq!(c.confidently_wrong, 1);
        assert!(!c.never_confidently_wrong());
        assert_eq!(c.max_z_exit0, Some(5.0));
        assert_eq!(c.max_z_all, Some(9.0));
        let b = bars([(&c, false)]);
        assert_eq!(b.confidently_wrong_cells, 1);
        assert!(!b.never_confidently_wrong() && !b.all_hold());
    }

    #[test]
    fn a_flagged_seed_far_off_is_not_confidently_wrong() {
        let c = cell_stats(&[seed(0, 1.0), seed(3, 9.0)]);
        assert_eq!(c.confidently_wrong, 0);
        assert!(c.never_confidently_wrong());
        assert_eq!(c.max_z_exit0, Some(1.0));
        assert_eq!(c.z_rms_exit0, Some(1.0), "the flagged seed's z stays out of the RMS");
        assert!(bars([(&c, false)]).all_hold());
    }

    #[test]
    fn exit_0_without_a_result_counts_as_infinitely_wrong() {
        let c = cell_stats(&[SeedOutcome { code: Some(0), z: None, cpu_s: Some(1.0) }]);
        assert_eq!(c.max_z_exit0, Some(f64::INFINITY));
        assert_eq!(c.confidently_wrong, 1);
        assert_eq!(c.max_z_all, None);
        assert_eq!(c.z_rms_exit0, None);
    }

    #[test]
    fn exit_statuses_are_counted() {
        let none = SeedOutcome::default();
        let c = cell_stats(&[seed(0, 1.0), seed(3, 1.0), seed(1, 1.0), none, seed(0, 1.0)]);
        assert_eq!((c.seeds, c.exit0, c.exit3, c.other), (5, 2, 1, 2));
        assert_eq!(c.calibrations, 4);
        assert_eq!(c.cpu_per_calibration(), 0.5);
        assert!(!c.all_exit0());
    }

    #[test]
    fn the_rms_bar_holds_only_within_its_range() {
        assert_eq!(cell_stats(&[seed(0, 0.5)]).rms_holds(), Some(false));
        assert_eq!(cell_stats(&[seed(0, 1.0)]).rms_holds(), Some(true));
        assert_eq!(cell_stats(&[seed(0, 1.4)]).rms_holds(), Some(false));
        assert_eq!(cell_stats(&[seed(3, 0.1)]).rms_holds(), None, "no exit-0 seed: nothing to judge");
        let low = cell_stats(&[seed(0, 0.5), seed(0, 0.6)]);
        let b = bars([(&low, false), (&cell_stats(&[seed(0, 1.0)]), false)]);
        assert_eq!((b.rms_cells, b.rms_outside), (2, 1));
        assert!(b.never_confidently_wrong() && !b.rms_holds() && !b.all_hold());
    }

    #[test]
    fn the_live_bar_wants_every_seed_at_exit_0() {
        let flagged = cell_stats(&[seed(0, 1.0), seed(3, 1.0)]);
        let clean = cell_stats(&[seed(0, 1.0), seed(0, 1.0)]);
        assert_eq!(bars([(&flagged, true), (&clean, true)]).live_holds(), Some(false));
        assert!(!bars([(&flagged, true)]).all_hold());
        assert_eq!(bars([(&flagged, false), (&clean, true)]).live_holds(), Some(true));
        assert_eq!(bars([(&clean, false)]).live_holds(), None, "no live cell ran");
        assert!(bars([(&flagged, false)]).all_hold(), "a flagged seed off the live design is honest");
    }
}

mod remix {
    use crate::measured::remix::*;
    use nalgebra::{Matrix3, Vector3};
    use protocol::RigMsg;
    use serde_json::json;

    fn demo() -> Vec<u8> {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/demo.cap");
        std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"))
    }

    /// Every frame of a capture, in order.
    fn frames(bytes: &[u8]) -> Vec<(u16, RigMsg)> {
        crate::measured::remix::frames("capture", bytes).unwrap_or_else(|e| panic!("{e}"))
    }

    /// A = I without noise gives the capture back byte for byte: the frames are re-encoded as
    /// the rig encoded them.
    #[test]
    fn the_identity_gives_the_capture_back() {
        let bytes = demo();
        let id = Remix { a: Matrix3::identity(), noise_counts: 0.0, seed: 1, cut_s: None };
        let (out, held) = id.capture("demo.cap", &bytes).expect("a clean capture");
        assert_eq!(held, 0);
        assert!(out == bytes, "{} bytes against {}", out.len(), bytes.len());
    }

    /// Each sample's counts are round(A·counts), held to the i16 range (a 3× gain clips the demo's
    /// larger counts); every other frame and every sequence number is unchanged.
    #[test]
    fn every_sample_goes_through_a_and_nothing_else_moves() {
        let bytes = demo();
        let a = Matrix3::new(3.0, 0.01, -0.02, 0.005, 0.98, 0.0, -0.01, 0.03, 1.02);
        let (out, held) =
            Remix { a, noise_counts: 0.0, seed: 1, cut_s: None }.capture("demo.cap", &bytes).expect("clean");
        let (before, after) = (frames(&bytes), frames(&out));
        assert_eq!(before.len(), after.len());
        let (mut samples, mut want_held) = (0, 0);
        for ((seq0, m0), (seq1, m1)) in before.iter().zip(&after) {
            assert_eq!(seq0, seq1);
            match (m0, m1) {
                (RigMsg::Sample(s0), RigMsg::Sample(s1)) => {
                    let x = a * Vector3::from(s0.rate_counts.map(f64::from));
                    for (got, want) in s1.rate_counts.iter().zip(x.iter()) {
                        let r = want.round();
                        want_held += u64::from(!(-32768.0..=32767.0).contains(&r));
                        assert_eq!(f64::from(*got), r.clamp(-32768.0, 32767.0));
                    }
                    assert_eq!((s0.t_us, s0.encoder, s0.status), (s1.t_us, s1.encoder, s1.status));
                    samples += 1;
                }
                _ => assert_eq!(m0, m1),
            }
        }
        assert!(samples > 10_000, "{samples} samples");
        assert_eq!(held, want_held);
        assert!(held > 0, "a 3× gain holds some counts at the rails");
    }

    /// The noise is a draw of its σ, and the same draw for the same seed and name.
    #[test]
    fn the_noise_has_its_sigma_and_its_seed() {
        let bytes = demo();
        let noisy = Remix { a: Matrix3::identity(), noise_counts: 3.0, seed: 7, cut_s: None };
        let (out, _) = noisy.capture("demo.cap", &bytes).expect("clean");
        assert!(out == noisy.capture("demo.cap", &bytes).expect("clean").0, "the same seed, the same draw");
        assert!(out != noisy.capture("other.cap", &bytes).expect("clean").0, "another name, another draw");
        let (mut sum_sq, mut n) = (0.0, 0.0);
        for ((_, m0), (_, m1)) in frames(&bytes).iter().zip(&frames(&out)) {
            if let (RigMsg::Sample(s0), RigMsg::Sample(s1)) = (m0, m1) {
                for (a, b) in s0.rate_counts.iter().zip(&s1.rate_counts) {
                    sum_sq += (f64::from(*b) - f64::from(*a)).powi(2);
                    n += 1.0;
                }
            }
        }
        // Rounded N(0, 3²) has variance 9 + 1/12; over n ≈ 10⁵ its estimate is within 1 %.
        let var = sum_sq / n;
        assert!((var - 9.083).abs() < 0.03 * 9.083, "variance {var} over {n} counts");
    }

    /// A cut keeps each run's first seconds and its `RunStopped` (moved to the cut), drops the
    /// rest of the run, keeps everything outside runs, and closes the sequence numbers' gap.
    #[test]
    fn a_cut_keeps_each_runs_first_seconds() {
        let bytes = demo();
        let cut_s = 3.0;
        let cut = Remix { a: Matrix3::identity(), noise_counts: 0.0, seed: 1, cut_s: Some(cut_s) };
        let (out, _) = cut.capture("demo.cap", &bytes).expect("clean");
        let (before, after) = (frames(&bytes), frames(&out));
        // The frames kept, in order: outside runs all of them; in a run those before its first
        // sample at or past the cut; its RunStopped at that sample's time.
        let (mut want, mut first, mut cut_at, mut runs) = (Vec::new(), None, None, 0);
        for (_, m) in &before {
            match m {
                RigMsg::RunStarted(_) => (first, cut_at, runs) = (None, None, runs + 1),
                RigMsg::RunStopped(stop) => {
                    let mut stop = *stop;
                    stop.t_us = cut_at.expect("demo's runs are longer than the cut");
                    want.push(RigMsg::RunStopped(stop));
                    (first, cut_at) = (None, None);
                    continue;
                }
                RigMsg::Sample(s) => {
                    let t0 = *first.get_or_insert(s.t_us);
                    if cut_at.is_none() && f64::from(s.t_us - t0) >= cut_s * 1e6 {
                        cut_at = Some(s.t_us);
                    }
                }
                _ => {}
            }
            if cut_at.is_none() {
                want.push(*m);
            }
        }
        assert!(runs >= 2 && want.len() < before.len(), "{runs} runs, {} of {} frames", want.len(), before.len());
        assert_eq!(after.iter().map(|(_, m)| *m).collect::<Vec<_>>(), want);
        for (i, (seq, _)) in after.iter().enumerate() {
            assert_eq!(*seq, before[0].0.wrapping_add(i as u16), "frame {i}: no gap in the sequence numbers");
        }
    }

    /// A grown effect: gain 0 gives the base back and gain 1 the capture with the effect, byte
    /// for byte; gain 3 puts each count at base + 3·(with − base); captures that are not the
    /// same frames are refused.
    #[test]
    fn an_effect_grows_by_its_difference_from_the_twin() {
        let base = demo();
        let a = Matrix3::new(1.01, 0.002, 0.0, 0.0, 0.995, -0.003, 0.001, 0.0, 1.0);
        let (with, _) = Remix { a, noise_counts: 0.0, seed: 1, cut_s: None }.capture("demo.cap", &base).expect("clean");
        assert!(grown("demo.cap", &base, &with, 0.0).expect("twins") == base, "gain 0: the base");
        assert!(grown("demo.cap", &base, &with, 1.0).expect("twins") == with, "gain 1: the capture");
        let tripled = grown("demo.cap", &base, &with, 3.0).expect("twins");
        let (mut moved, mut samples) = (0, 0);
        for (((s0, b), (_, w)), (s3, g)) in frames(&base).iter().zip(&frames(&with)).zip(&frames(&tripled)) {
            assert_eq!(s0, s3);
            match (b, w, g) {
                (RigMsg::Sample(b), RigMsg::Sample(w), RigMsg::Sample(g)) => {
                    for i in 0..3 {
                        let (cb, cw) = (i32::from(b.rate_counts[i]), i32::from(w.rate_counts[i]));
                        let want = (cb + 3 * (cw - cb)).clamp(-32768, 32767);
                        assert_eq!(i32::from(g.rate_counts[i]), want);
                        moved += usize::from(cw != cb);
                    }
                    samples += 1;
                }
                _ => assert_eq!(b, g),
            }
        }
        assert!(samples > 10_000 && moved > samples, "{moved} counts moved in {samples} samples");
        let cut = Remix { a: Matrix3::identity(), noise_counts: 0.0, seed: 1, cut_s: Some(3.0) };
        let (short, _) = cut.capture("demo.cap", &base).expect("clean");
        let err = grown("demo.cap", &base, &short, 2.0).expect_err("not twins");
        assert!(err.starts_with("demo.cap: ") && err.contains("frames against"), "{err}");
    }

    /// A capture with damaged bytes is refused, saying where.
    #[test]
    fn a_damaged_capture_is_refused() {
        let mut bytes = demo();
        bytes[1000] ^= 0x5a;
        let id = Remix { a: Matrix3::identity(), noise_counts: 0.0, seed: 1, cut_s: None };
        let err = id.capture("demo.cap", &bytes).expect_err("damaged");
        assert!(err.starts_with("demo.cap: ") && err.contains("bytes at offset"), "{err}");
    }

    /// The truth moves exactly: M' = A·M, v_off' = A·v_off, k' the rows' norms, S' unit rows.
    #[test]
    fn the_truth_is_the_mixed_sensors() {
        let truth = json!({
            "sensor": {"M": [[57.0, 0.5, -0.1], [0.3, 56.0, 0.8], [-0.4, -0.7, 58.0]], "v_off": [10.0, -20.0, 5.0],
                       "k": [0.0, 0.0, 0.0], "S": [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], "fs_dps": 500.0},
            "units": "counts"
        });
        let a = Matrix3::new(1.02, 0.01, 0.0, -0.005, 0.99, 0.002, 0.0, 0.0, 1.0);
        let got = Remix { a, noise_counts: 3.0, seed: 4, cut_s: None }.truth(&truth).expect("a truth");
        let m = Matrix3::new(57.0, 0.5, -0.1, 0.3, 56.0, 0.8, -0.4, -0.7, 58.0);
        let want = a * m;
        let m2 = m_true(&got).expect("M");
        for i in 0..3 {
            let k = got["sensor"]["k"][i].as_f64().expect("k");
            assert!((k - want.row(i).norm()).abs() < 1e-12, "k {i}");
            let s: Vec<f64> = (0..3).map(|j| got["sensor"]["S"][i][j].as_f64().expect("S")).collect();
            for j in 0..3 {
                assert!((m2[i][j] - want[(i, j)]).abs() < 1e-12, "M {i} {j}");
                assert!((s[j] * k - want[(i, j)]).abs() < 1e-12, "S {i} {j}");
            }
        }
        let v = a * Vector3::new(10.0, -20.0, 5.0);
        assert_eq!(got["sensor"]["v_off"], json!([v[0], v[1], v[2]]));
        assert_eq!((got["sensor"]["fs_dps"].clone(), got["units"].clone()), (json!(500.0), json!("counts")));
        assert_eq!(got["remix"]["seed"], json!(4));
        assert!(Remix::drawn(1) == Remix::drawn(1) && Remix::drawn(1) != Remix::drawn(2));
    }
}
