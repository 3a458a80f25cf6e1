use mpm_geo::scene::Scene;
use mpm_geo::simulation::Simulation;
use mpm_solvers::{DirectSolver, SolverPolicy};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps: usize = args[2].parse().unwrap();
    let scene = Scene::load(std::path::Path::new(&args[1]), &[]).unwrap();
    let mut sim = Simulation::new(scene).unwrap();
    for _ in 0..steps { sim.step_once().unwrap(); }
    let n = sim.unknowns().unwrap();
    let (r0, k) = sim.linearize(&vec![0.0; n]).unwrap();
    let mut solver = DirectSolver::new(SolverPolicy::Lu);
    solver.factorize(&k, false).unwrap();
    let mut du = r0.clone();
    solver.solve_in_place(&mut du).unwrap();
    // iterate Newton manually from the first iterate
    let mut u = du.clone();
    for it in 0..6 {
        let (r, k) = sim.linearize(&u).unwrap();
        let norm: f64 = r.iter().map(|v| v * v).sum::<f64>().sqrt();
        let mut s = DirectSolver::new(SolverPolicy::Lu);
        s.factorize(&k, false).unwrap();
        let mut d = r.clone();
        s.solve_in_place(&mut d).unwrap();
        // directional FD
        for eps in [1e-6, 1e-8] {
            let up: Vec<f64> = u.iter().zip(&d).map(|(a, b)| a + eps * b).collect();
            let (rp, _) = sim.linearize(&up).unwrap();
            let mut kd = vec![0.0; n];
            k.mul_vec(&d, &mut kd);
            let fd: Vec<f64> = rp.iter().zip(&r).map(|(a, b)| -(a - b) / eps).collect();
            let err: f64 = fd.iter().zip(&kd).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
            let sc: f64 = kd.iter().map(|v| v * v).sum::<f64>().sqrt();
            let worst = fd.iter().zip(&kd).enumerate().map(|(i, (a, b))| (i, (a - b).abs())).fold((0, 0.0), |m, x| if x.1 > m.1 { x } else { m });
            println!("it {it} |R| {norm:.4e} eps {eps:e}: |FD - K d|/|K d| = {:.3e} worst dof {:?}", err / sc, worst);
        }
        for (a, b) in u.iter_mut().zip(&d) { *a += b; }
    }
}
