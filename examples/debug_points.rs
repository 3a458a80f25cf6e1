use mpm_geo::constitutive::hmc::{Hmc, HmcParameters};
use mpm_geo::scene::Scene;
use mpm_geo::simulation::Simulation;
use mpm_geo::transfer;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps: usize = args[2].parse().unwrap();
    let scene = Scene::load(std::path::Path::new(&args[1]), &[]).unwrap();
    let mut sim = Simulation::new(scene).unwrap();
    for _ in 0..steps { sim.step_once().unwrap(); }
    let hmc = Hmc::new(HmcParameters::table1()).unwrap();
    // use the last increment's strain field as a representative increment
    let shapes = transfer::shapes_at(&sim.grid, &sim.particles.position).unwrap();
    let mut worst = vec![];
    for p in 0..sim.particles.len() {
        let l = transfer::gradient(&shapes[p], &sim.last_increment);
        let (de, _) = transfer::strain_and_spin(&l);
        let s = sim.particles.stress[p];
        let st = sim.particles.state[p];
        let (u, sub) = hmc.update_with_substeps(&s, &de, &st, None).unwrap();
        let mut err = 0.0f64; let mut scale = 0.0f64;
        for j in 0..4 {
            let eta = 1e-8;
            let mut a = de; a[j] += eta; let mut b = de; b[j] -= eta;
            let sa = hmc.update_with_substeps(&s, &a, &st, None).unwrap().0.stress;
            let sb = hmc.update_with_substeps(&s, &b, &st, None).unwrap().0.stress;
            for i in 0..4 { let fd = (sa[i]-sb[i])/(2.0*eta); err = err.max((fd - u.tangent[i][j]).abs()); scale = scale.max(u.tangent[i][j].abs()); }
        }
        worst.push((err/scale.max(1.0), p, sub, st.plastic_strain_eq, u.yielded, s));
    }
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    for w in worst.iter().take(3) { println!("{:?}", w); }
    let tension: Vec<usize> = (0..sim.particles.len()).filter(|&p| mpm_geo::constitutive::mean_stress(&sim.particles.stress[p]) < 1.0).collect();
    println!("points with p < 1 kPa: {}", tension.len());
    for &p in tension.iter().take(10) { println!("  p {} x {:?} stress {:?} kappa {}", p, sim.particles.position[p], sim.particles.stress[p], sim.particles.state[p].plastic_strain_eq); }
    let mut k: Vec<(f64, usize)> = (0..sim.particles.len()).map(|p| (sim.particles.state[p].plastic_strain_eq, p)).collect();
    k.sort_by(|a, b| b.0.total_cmp(&a.0));
    for &(kk, p) in k.iter().take(10) { println!("  kappa {kk:.4} p {} x {:?} stress {:?}", p, sim.particles.position[p], sim.particles.stress[p]); }
}
#[allow(dead_code)]
fn unused() {}
