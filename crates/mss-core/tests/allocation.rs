//! The hot paths allocate nothing once set up: an explicit step (with
//! contact, damping and the step control's checks) and a force evaluation
//! into a caller's buffer. Counted with a global allocator that tallies
//! every allocation of this test binary; the test runs alone in it, on one
//! thread, so nothing else allocates meanwhile.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

use mss_core::contact::{Contact, ContactSettings, Plane};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::solver::{Explicit, ExplicitOptions, Integrator, Problem, State};
use mss_core::{Material, Model, Vec3};

struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.load(Ordering::Relaxed)
}

#[test]
fn explicit_steps_and_force_passes_do_not_allocate() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| {
        let lattice = hexmesh::Lattice::block([8, 8, 4], 0.01, [0.0, 0.0, 0.002]).unwrap();
        let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
        let model = Model::new(&lattice, Material::new(2e4, 0.3, 1000.0).unwrap(), &param).unwrap();
        let settings = ContactSettings::for_model(&model);
        let ground = Plane::new(Vec3::zeros(), Vec3::z()).unwrap();
        let contact = Contact::new(&model, vec![(Box::new(ground), settings)]);
        let problem = Problem::from_specs(
            model,
            &[],
            &[LoadSpec::Gravity {
                g: [0.0, 0.0, -9.81],
            }],
            Damping {
                alpha: 2.0,
                beta: 1e-4,
            },
        )
        .unwrap()
        .with_contact(contact);
        let mut state = State::at_rest(problem.model());
        problem.apply_constraints(&mut state);
        let mut integ = Explicit::new(&problem, ExplicitOptions::default()).unwrap();
        // Set-up: the first steps, one of them checked, build what is
        // reused (the damping matrix, the friction anchors, the fallback
        // state's anchors).
        for k in 0..5 {
            if k == 2 {
                integ.check_next_step();
            }
            integ.step(&problem, &mut state).unwrap();
        }
        let before = allocations();
        let mut lowest = f64::INFINITY;
        for k in 0..200 {
            if k % 10 == 0 {
                integ.check_next_step();
            }
            integ.step(&problem, &mut state).unwrap();
            lowest = state.x.iter().map(|v| v.z).fold(lowest, f64::min);
        }
        let steps = allocations() - before;
        // It fell onto the ground and touched it (penalty contact: a node
        // went below the plane), whether or not it is bouncing now.
        assert!(lowest < 0.0, "{lowest}");
        let model = problem.model();
        let mut ws = model.workspace();
        let mut f = vec![Vec3::zeros(); model.num_nodes()];
        let before = allocations();
        for _ in 0..20 {
            model.internal_forces_with(&state.x, &mut ws, &mut f);
        }
        let forces = allocations() - before;
        assert_eq!(
            (steps, forces),
            (0, 0),
            "allocations in 200 steps, in 20 force passes"
        );
    });
}
