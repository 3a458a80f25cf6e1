//! The `mpm-geo point ...` subcommand: the options of the homogeneous
//! single-material-point tests, and the CSV they write; the loops themselves
//! are [`mpm_physics::point_driver`]'s.

use std::path::{Path, PathBuf};

use crate::constitutive::hmc::Hmc;
use crate::csv_columns::number;
use crate::point_driver::{
    load_parameters, run_biaxial, run_simple_shear, run_triaxial, PointDriverError, PointRecord,
};

/// Which homogeneous test to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PointTest {
    /// Plane strain (εzz = 0, γxy = 0), σxx = −confinement held, εyy driven (compression).
    Biaxial,
    /// σxx = σzz = −confinement held, εyy driven (compression), γxy = 0.
    Triaxial,
    /// γxy driven, εxx = εyy = εzz = 0.
    SimpleShear,
}

/// Command-line options of the material-point driver (`mpm-geo point ...`).
#[derive(Clone, Debug, clap::Args)]
pub struct PointArgs {
    /// Test path.
    #[arg(long, value_enum, default_value = "biaxial")]
    pub test: PointTest,
    /// Confining pressure (kPa, compression positive); also the initial isotropic stress.
    #[arg(long, default_value_t = 100.0, value_parser = crate::cli_values::number)]
    pub confinement: f64,
    /// Final axial strain magnitude −εyy (biaxial, triaxial) or shear strain γxy (simple shear).
    /// Default 0.0452 = 2.26 mm / 0.05 m, the end of the paper's biaxial test.
    #[arg(long, default_value_t = 0.0452, value_parser = crate::cli_values::number)]
    pub strain: f64,
    /// Number of equal strain steps.
    #[arg(long, default_value_t = 2260, value_parser = crate::cli_values::count)]
    pub steps: usize,
    /// TOML file with HmcParameters keys at top level (missing keys keep Table 1 values).
    #[arg(long)]
    pub material: Option<PathBuf>,
    /// Override one parameter, e.g. `--set omega=0.5` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Output CSV file.
    #[arg(long, default_value = "point.csv")]
    pub out: PathBuf,
}

/// Write the records as CSV: step, strains, stresses (kPa), p, q, κ, F
/// (kN/m), yielded (1 or 0); every column named with its unit
/// ([`crate::csv_columns`]).
pub fn write_csv(path: &Path, records: &[PointRecord]) -> Result<(), PointDriverError> {
    let err = |e: csv::Error| PointDriverError::Write {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let io = |e: std::io::Error| PointDriverError::Write {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    // whole or absent: renamed to its name once every row is written
    let file = crate::atomic_file::AtomicFile::create(path).map_err(io)?;
    let mut writer = csv::Writer::from_writer(file);
    writer
        .write_record([
            "step_1",
            "eps_xx_1",
            "eps_yy_1",
            "eps_zz_1",
            "gamma_xy_1",
            "sig_xx_kPa",
            "sig_yy_kPa",
            "sig_zz_kPa",
            "sig_xy_kPa",
            "p_kPa",
            "q_kPa",
            "kappa_1",
            "F_kN_per_m",
            "yielded_1",
        ])
        .map_err(err)?;
    for r in records {
        let mut row = vec![r.step.to_string()];
        row.extend(r.strain.iter().map(|&x| number(x)));
        row.extend(r.stress.iter().map(|&x| number(x)));
        for x in [
            r.mean_stress,
            r.deviatoric_stress,
            r.plastic_strain_eq,
            r.load,
        ] {
            row.push(number(x));
        }
        row.push(u8::from(r.yielded).to_string());
        writer.write_record(&row).map_err(err)?;
    }
    let file = writer.into_inner().map_err(|e| io(e.into_error()))?;
    file.commit().map_err(io)
}

/// Run the test selected by `args` and write the CSV (`mpm-geo point ...`).
pub fn run(args: &PointArgs) -> Result<(), PointDriverError> {
    if !(args.confinement.is_finite() && args.confinement >= 0.0) {
        return Err(PointDriverError::InvalidOption(format!(
            "--confinement = {} must be a finite pressure >= 0 kPa",
            args.confinement
        )));
    }
    if !(args.strain.is_finite() && args.strain > 0.0) {
        return Err(PointDriverError::InvalidOption(format!(
            "--strain = {} must be finite and > 0",
            args.strain
        )));
    }
    if args.steps == 0 {
        return Err(PointDriverError::InvalidOption(
            "--steps must be >= 1".into(),
        ));
    }
    let parameters = load_parameters(args.material.as_deref(), &args.set)?;
    let model = Hmc::new(parameters).map_err(PointDriverError::InvalidParameters)?;
    let n = args.steps as f64;
    let sign = if args.test == PointTest::SimpleShear {
        1.0
    } else {
        -1.0
    };
    let targets: Vec<f64> = (1..=args.steps)
        .map(|k| sign * args.strain * k as f64 / n)
        .collect();
    let records = match args.test {
        PointTest::Biaxial => run_biaxial(&model, args.confinement, &targets)?,
        PointTest::Triaxial => run_triaxial(&model, args.confinement, &targets)?,
        PointTest::SimpleShear => run_simple_shear(&model, args.confinement, &targets)?,
    };
    write_csv(&args.out, &records)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constitutive::hmc::HmcParameters;

    fn table1() -> Hmc {
        Hmc::new(HmcParameters::table1()).unwrap()
    }

    /// The clap arguments parse as documented (defaults, value names, repeatable --set).
    #[test]
    fn clap_arguments() {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            point: PointArgs,
        }
        let cli = Cli::try_parse_from(["mpm-geo"]).unwrap();
        assert_eq!(cli.point.test, PointTest::Biaxial);
        assert_eq!(
            (cli.point.confinement, cli.point.strain, cli.point.steps),
            (100.0, 0.0452, 2260)
        );
        assert_eq!(cli.point.out, PathBuf::from("point.csv"));
        let cli = Cli::try_parse_from([
            "mpm-geo",
            "--test",
            "simple-shear",
            "--set",
            "omega=0.5",
            "--set",
            "b_res=1",
            "--strain",
            "0.2",
        ])
        .unwrap();
        assert_eq!(cli.point.test, PointTest::SimpleShear);
        assert_eq!(
            cli.point.set,
            vec!["omega=0.5".to_string(), "b_res=1".to_string()]
        );
        assert!(Cli::try_parse_from(["mpm-geo", "--test", "oedometer"]).is_err());
    }

    /// Simple shear keeps εxx = εyy = εzz = 0 and stays on the surface; the driver writes a CSV with
    /// one header and steps + 1 rows; bad options and parameters are reported as errors, not panics.
    #[test]
    fn driver_cli_and_csv() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("shear.csv");
        let args = PointArgs {
            test: PointTest::SimpleShear,
            confinement: 100.0,
            strain: 0.1,
            steps: 50,
            material: None,
            set: vec!["omega=0.5".into()],
            out: out.clone(),
        };
        run(&args).unwrap();
        let text = std::fs::read_to_string(&out).unwrap();
        assert_eq!(text.lines().count(), 52);
        assert!(text.starts_with("step_1,eps_xx_1,eps_yy_1,eps_zz_1,gamma_xy_1,sig_xx_kPa"));
        let m = table1();
        let recs = run_simple_shear(&m, 100.0, &[0.01, 0.02, 0.05]).unwrap();
        assert!(recs
            .iter()
            .all(|r| r.strain[0] == 0.0 && r.strain[1] == 0.0 && r.strain[2] == 0.0));
        let last = recs.last().unwrap();
        assert!(m.yield_function(&last.stress, last.plastic_strain_eq).abs() <= 1e-8 * 200.0);

        let material = dir.path().join("m.toml");
        std::fs::write(&material, "c_ini = 150.0\nb_post = 5.0\n").unwrap();
        let p = load_parameters(Some(&material), &["phi_res=18".into()]).unwrap();
        assert_eq!(
            (p.cohesion_ini, p.softening_rate_post, p.friction_angle_res),
            (150.0, 5.0, 18.0)
        );
        let bad = |set: &str| {
            load_parameters(None, &[set.to_string()])
                .unwrap_err()
                .to_string()
        };
        assert!(bad("omega").contains("KEY=VALUE"));
        assert!(bad("omega=2").contains("material.omega"));
        assert!(bad("phi_post=3").contains("phi_post"));
        // a misspelt key gets the one meant (issue 41, item 11)
        assert!(
            bad("omga=0.5").contains("unknown key `omga`; did you mean `omega`?"),
            "{}",
            bad("omga=0.5")
        );
        let mut bad_args = args.clone();
        bad_args.steps = 0;
        assert!(run(&bad_args).is_err());
        bad_args = args;
        bad_args.material = Some(dir.path().join("missing.toml"));
        assert!(matches!(
            run(&bad_args),
            Err(PointDriverError::ReadMaterial { .. })
        ));
    }
}
