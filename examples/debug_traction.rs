use mpm_geo::scene::Scene;
use mpm_geo::simulation::Simulation;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps: usize = args[2].parse().unwrap();
    let k: usize = args[3].parse().unwrap();
    let scene = Scene::load(std::path::Path::new(&args[1]), &[]).unwrap();
    let mut sim = Simulation::new(scene).unwrap();
    for s in 0..steps {
        if sim.step_once().is_err() { break; }
        if s % 5 == 0 || s > steps - 8 {
            println!("{s} pt {k}: {:?} t {:?}", sim.traction.position[k], sim.traction.tangent[k]);
            let (node, m) = sim.last_increment.iter().enumerate().map(|(i, u)| (i, (u[0]*u[0]+u[1]*u[1]).sqrt())).fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
            println!("   max |du| {m:.3e} at node {:?}", sim.grid.node_position(node));
        }
    }
}
