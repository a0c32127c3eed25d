//! The `uavgen` command line.

mod cli;

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;
use uavgen::codegen::{Float, GenerateOptions, QpChoice};
use uavgen::model::pysindy::{import, ImportOptions, KinematicRows};

#[derive(Parser)]
#[command(
    name = "uavgen",
    version,
    about = "Generate no_std MPC crates for UAV models",
    args_conflicts_with_subcommands = true,
    // `--horizon -1` is a bad value of --horizon (named in the message), not an unknown flag `-1`.
    allow_negative_numbers = true
)]
struct Cli {
    /// No progress bars or spinners on stderr (they are only drawn when stderr is a terminal
    /// anyway); results, warnings and errors are printed as always.
    #[arg(long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    generate: GenerateArgs,
}

#[derive(Subcommand)]
enum Command {
    /// Convert a PySINDy export (scripts/export_pysindy.py) to a uavgen-model/1 file.
    #[command(allow_negative_numbers = true)]
    ImportPysindy(ImportArgs),
    /// Validate a model file and print its summary (sizes, sparsity, substeps): runs exactly what generation runs, in memory, and writes nothing.
    #[command(allow_negative_numbers = true)]
    Check(CheckArgs),
    /// Worst-case benchmark of a generated crate (see docs/benchmarks.md).
    #[command(allow_negative_numbers = true)]
    Bench(BenchArgs),
    /// Identify a SINDy or PD model from flight logs (docs/identification.md).
    #[command(allow_negative_numbers = true)]
    Identify(cli::identify::IdentifyArgs),
    /// Evaluate a model's predictions against flight logs: one-step, horizon and whole-flight metrics.
    #[command(allow_negative_numbers = true)]
    Evaluate(cli::evaluate::EvaluateArgs),
    /// Simulate a flight with a plant file (vehicle, autopilot, effects) and write a flight log (docs/simulate.md).
    #[command(allow_negative_numbers = true)]
    Simulate(cli::simulate::SimulateArgs),
    /// Closed-loop MPC on the plant simulator along one of the paper's trajectories (docs/track.md).
    #[command(allow_negative_numbers = true)]
    Track(cli::track::TrackArgs),
    /// Import a PX4 ULog, MCAP (ROS 2), ROS 1 bag or ArduPilot DataFlash recording as a flight log CSV, mapped by a profile (docs/import.md).
    #[command(allow_negative_numbers = true)]
    Import(cli::import::ImportArgs),
    /// Diagnose a model on flight logs: where it parts from the data, which effect explains it, the corrected model (docs/diagnose.md).
    #[command(allow_negative_numbers = true)]
    Diagnose(cli::diagnose::DiagnoseArgs),
    /// The operating envelope of flight logs (observed range per state, widened), printed or written into a model file as identify does (docs/model-format.md#envelope).
    #[command(allow_negative_numbers = true)]
    Envelope(cli::envelope::EnvelopeArgs),
}

#[derive(Args)]
struct BenchArgs {
    /// The generated crate to benchmark.
    #[arg(long = "crate")]
    crate_dir: PathBuf,
    /// Its model file: also time the generic reference solver (interpreted + clarabel) side by side.
    #[arg(long)]
    model: Option<PathBuf>,
    /// RTI steps per trajectory (3 trajectories).
    #[arg(long, default_value_t = 3334)]
    steps: usize,
    /// Steps per trajectory for the generic solver.
    #[arg(long, default_value_t = 100)]
    generic_steps: usize,
    /// Count instructions of this many RTI steps per trajectory (3 trajectories, as timed) under callgrind (0: skip).
    #[arg(long, default_value_t = 0)]
    instructions: usize,
    /// Also count the instructions of this many trials of the adversarial search under callgrind (0: skip).
    #[arg(long, default_value_t = 0)]
    adversarial: usize,
    /// Build with -C target-cpu=native (this machine's vector units; valgrind 3.19 cannot run AVX-512
    /// code, so count instructions with --target-cpu skylake instead).
    #[arg(long, conflicts_with = "target_cpu")]
    native: bool,
    /// Build with -C target-cpu=CPU (e.g. skylake: AVX2 and FMA units, no AVX-512, which valgrind 3.19
    /// can count; its x86-64-v3 code contains an encoding valgrind 3.19 rejects).
    #[arg(long, value_name = "CPU")]
    target_cpu: Option<String>,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Scratch directory for the harness crate and its build.
    #[arg(long, default_value = "target/uavgen-bench")]
    work_dir: PathBuf,
    /// Also build a Cortex-M7 firmware (thumbv7em-none-eabihf) holding the solver and report its flash
    /// and RAM (needs `rustup target add thumbv7em-none-eabihf`).
    #[arg(long)]
    flash: bool,
    /// This machine's peak f64 rate in GFlop/s (lanes × FMA units × 2 × clock): with --model, the
    /// achieved rate of `prepare` is also given as a fraction of it.
    #[arg(long)]
    peak_gflops: Option<f64>,
    /// Also write the results as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Overwrite --json if it exists.
    #[arg(long)]
    force: bool,
}

#[derive(Args)]
struct GenerateArgs {
    /// Model file (uavgen-model/1 JSON).
    #[arg(long)]
    model: Option<PathBuf>,
    /// MPC horizon N in samples.
    #[arg(long, default_value_t = 30)]
    horizon: usize,
    /// Sample rate in Hz.
    #[arg(long, default_value_t = 30.0)]
    rate: f64,
    /// RK4 substeps per sample (default: chosen automatically, see docs/discretisation.md).
    #[arg(long)]
    substeps: Option<usize>,
    /// Floating-point type of the generated code.
    #[arg(long, value_enum, default_value_t = FloatArg::F64)]
    float: FloatArg,
    /// Crate name (default: the model name).
    #[arg(long)]
    crate_name: Option<String>,
    /// Output directory (default: ./<crate name>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// QP solver of the generated crate: `condensed` (dense box QP in the N·NU inputs, primal
    /// active set), `riccati` (stage-wise primal-dual interior point, Riccati recursion, at most
    /// max_ipm_iterations iterations; a third of the memory) or `auto` (the one whose typical QP
    /// work per step is smaller in flops, the input-rate term counted; docs/mpc.md).
    #[arg(long, value_enum, default_value_t = QpArg::Auto)]
    qp: QpArg,
    /// Regenerate even if --out, a crate uavgen generated, holds files uavgen did not write (they are deleted).
    #[arg(long)]
    force: bool,
    /// MPC options file: weights, input bounds, QP limits (default: the paper's but q yaw 1, r u_yaw_rate 10, input-rate weight r_delta 50 on u_roll and u_pitch; examples/mpc_paper.json has the paper's; see docs/mpc.md).
    #[arg(long)]
    mpc: Option<PathBuf>,
    /// Also emit a C ABI: include/<name>.h and the capi/ package (staticlib lib<name>_capi.a) for C/C++ flight stacks (docs/c-api.md).
    #[arg(long)]
    c_api: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum QpArg {
    Auto,
    Condensed,
    Riccati,
}

#[derive(Clone, Copy, ValueEnum)]
enum FloatArg {
    F64,
    F32,
}

#[derive(Args)]
struct ImportArgs {
    /// JSON export of a fitted PySINDy model.
    #[arg(long)]
    input: PathBuf,
    /// Name of the model.
    #[arg(long)]
    name: String,
    /// Output model file.
    #[arg(long)]
    out: PathBuf,
    /// How rows PySINDy did not fit are completed.
    #[arg(long, value_enum, default_value_t = KinematicArg::Auto)]
    kinematic: KinematicArg,
    /// Overwrite --out if it exists.
    #[arg(long)]
    force: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum KinematicArg {
    /// Standard position/angle states that were not fitted become kinematic.
    Auto,
    /// Only the rows the export lists.
    None,
}

#[derive(Args)]
struct CheckArgs {
    /// Model file.
    #[arg(long)]
    model: PathBuf,
    /// Sample rate in Hz for the substep rule.
    #[arg(long, default_value_t = 30.0)]
    rate: f64,
    /// MPC horizon N in samples (as for generation).
    #[arg(long, default_value_t = 30)]
    horizon: usize,
    /// RK4 substeps per sample (default: chosen automatically, see docs/discretisation.md).
    #[arg(long)]
    substeps: Option<usize>,
    /// Floating-point type of the generated code.
    #[arg(long, value_enum, default_value_t = FloatArg::F64)]
    float: FloatArg,
    /// MPC options file (see docs/mpc.md).
    #[arg(long)]
    mpc: Option<PathBuf>,
}

/// Let a closed pipe end the program quietly, as it ends `cat` (`uavgen simulate ... | head`):
/// Rust ignores SIGPIPE, so every `println!` after the reader left would panic instead.
#[cfg(unix)]
fn default_sigpipe() {
    extern "C" {
        fn signal(signum: i32, handler: usize) -> usize;
    }
    const SIGPIPE: i32 = 13;
    const SIG_DFL: usize = 0;
    // SAFETY: restoring the default disposition of one signal before any thread is started.
    unsafe {
        signal(SIGPIPE, SIG_DFL);
    }
}

#[cfg(not(unix))]
fn default_sigpipe() {}

fn main() -> ExitCode {
    default_sigpipe();
    // Ctrl-C, SIGTERM and SIGHUP wait for an output being put in place and leave nothing partial
    // (uavgen::interrupt, docs/cli.md "Files"). Without a handler (it cannot be installed) the
    // next run still removes what an interrupted one left.
    let _ = ctrlc::set_handler(|| uavgen::interrupt::on_signal());
    let cli = Cli::parse();
    cli::progress::set_quiet(cli.quiet);
    let result = match cli.command {
        Some(Command::ImportPysindy(args)) => import_pysindy(args),
        Some(Command::Check(args)) => check(args),
        Some(Command::Bench(args)) => bench(args),
        Some(Command::Identify(args)) => cli::identify::run(args),
        Some(Command::Evaluate(args)) => cli::evaluate::run(args),
        Some(Command::Simulate(args)) => cli::simulate::run(args),
        Some(Command::Track(args)) => match cli::track::run(args) {
            // The verdicts' exit status (0, 3 or 4; docs/track.md).
            Ok(code) => return code,
            Err(e) => Err(e),
        },
        Some(Command::Diagnose(args)) => cli::diagnose::run(args),
        Some(Command::Import(args)) => cli::import::run(args),
        Some(Command::Envelope(args)) => cli::envelope::run(args),
        None => generate(cli.generate),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

fn generate(args: GenerateArgs) -> Result<(), String> {
    let path = args.model.ok_or("--model is required (see `uavgen --help`)")?;
    let model = uavgen::load(&path).map_err(|e| e.to_string())?;
    let mpc = match &args.mpc {
        Some(p) => Some(uavgen::MpcOptions::load(&model, p)?),
        None => None,
    };
    let options = GenerateOptions {
        mpc,
        horizon: args.horizon,
        rate_hz: args.rate,
        substeps: args.substeps,
        float: match args.float {
            FloatArg::F64 => Float::F64,
            FloatArg::F32 => Float::F32,
        },
        crate_name: args.crate_name,
        c_api: args.c_api,
        qp: match args.qp {
            QpArg::Auto => QpChoice::Auto,
            QpArg::Condensed => QpChoice::Condensed,
            QpArg::Riccati => QpChoice::Riccati,
        },
        ..GenerateOptions::default()
    };
    let written = uavgen::commands::generate::generate_into(
        &model,
        &path.display().to_string(),
        &options,
        args.out.as_deref(),
        args.force,
        |work| cli::progress::with_spinner("generating (substep rule, Jacobians, code)", work),
    )?;
    for line in written.summary(&model, &options) {
        println!("{line}");
    }
    Ok(())
}

fn import_pysindy(args: ImportArgs) -> Result<(), String> {
    let label = args.input.display().to_string();
    let text = std::fs::read_to_string(&args.input).map_err(|e| format!("{label}: cannot read: {e}"))?;
    let options = ImportOptions {
        name: args.name,
        kinematic: match args.kinematic {
            KinematicArg::Auto => KinematicRows::Auto,
            KinematicArg::None => KinematicRows::None,
        },
        drop_below: 0.0,
    };
    cli::refuse_existing(&args.out, args.force)?;
    let file = import(&text, &label, &options).map_err(|e| e.to_string())?;
    let json = serde_json::to_string_pretty(&file).map_err(|e| e.to_string())? + "\n";
    // Validate the result exactly as `--model` would read it before writing anything.
    uavgen::model::parse(&json, &label).map_err(|e| format!("the imported model is invalid: {e}"))?;
    cli::write_atomically(&args.out, &json)?;
    println!(
        "wrote {} ({} coefficients, {} library terms)",
        args.out.display(),
        file.coefficients.len(),
        file.library.len()
    );
    Ok(())
}

fn check(args: CheckArgs) -> Result<(), String> {
    let options = GenerateOptions {
        rate_hz: args.rate,
        horizon: args.horizon,
        substeps: args.substeps,
        float: match args.float {
            FloatArg::F64 => Float::F64,
            FloatArg::F32 => Float::F32,
        },
        ..GenerateOptions::default()
    };
    options.validate().map_err(|e| e.to_string())?;
    let model = uavgen::load(&args.model).map_err(|e| e.to_string())?;
    let options = GenerateOptions {
        mpc: match &args.mpc {
            Some(p) => Some(uavgen::MpcOptions::load(&model, p)?),
            None => None,
        },
        ..options
    };
    let ir = uavgen::ModelIr::new(&model);
    println!(
        "{}: model '{}' ({}), {} states, {} inputs",
        args.model.display(),
        model.name,
        model.kind_name(),
        model.nx(),
        model.nu()
    );
    for line in model.corrections_summary() {
        println!("  {line}");
    }
    println!(
        "  symbolic graph: {} nodes; Jacobian [∂f/∂x ∂f/∂u]: {} structural non-zeros of {}",
        ir.graph.len(),
        ir.jacobian_nonzeros(),
        model.nx() * (model.nx() + model.nu())
    );
    // Exactly what `uavgen --model` runs, in memory: whatever generation would refuse, check refuses.
    let generated = cli::progress::with_spinner("generating in memory (substep rule, Jacobians, code)", || {
        uavgen::generate(&model, &options)
    })
    .map_err(|e| format!("{}: {e}", args.model.display()))?;
    match &generated.substep_choice {
        Some(c) => println!(
            "  RK4 at {} Hz: {} substeps (stiffest eigenvalue {:.2}{:+.2}i 1/s over {} envelope points)",
            args.rate, generated.substeps, c.stiffest.re, c.stiffest.im, c.points
        ),
        None => println!("  RK4 at {} Hz: {} substeps (given)", args.rate, generated.substeps),
    }
    println!(
        "  generation: ok (crate `{}`, {} files, N = {}, qp = {})",
        generated.crate_name,
        generated.files.len(),
        options.horizon,
        generated.qp.name()
    );
    let s = &generated.structure;
    let (nza, nzb) = s.nonzeros();
    let (after, dense) = (
        s.flops(options.horizon),
        uavgen::codegen::kernels::Structure::dense(s.nx, s.nu).flops(options.horizon),
    );
    let (lin, lin_dense) = generated
        .sensitivity_flops
        .per_step(options.horizon, generated.substeps);
    println!(
        "  linearisation: multiply-adds per RTI step of the emitted sensitivity kernels (∂f/∂x·S and the RK4 \
         combinations, model evaluation not counted): {lin} (all columns {lin_dense})"
    );
    println!(
        "  structure: A {nza} of {}, B {nzb} of {} structural non-zeros, input components {:?}; multiply-adds per RTI step of the emitted \
         kernels (condensed QP): condensing {} (dense {}), feedback {} (dense {}), Cholesky of H with every input free {} (dense {}), total {} (dense {})",
        s.nx * s.nx,
        s.nx * s.nu,
        s.input_components(),
        after.condensing,
        dense.condensing,
        after.feedback,
        dense.feedback,
        after.cholesky,
        dense.cholesky,
        after.total(),
        dense.total()
    );
    println!(
        "  multiply-adds per RTI step without the QP's iterations (linearisation + condensing + feedback + Cholesky): \
         {} (without the structural specialisation {})",
        uavgen::bench::StepWork::of(&generated, options.horizon).total(),
        lin_dense + dense.total()
    );
    Ok(())
}

/// Print the step's arithmetic against its instruction count and time; the same as JSON.
fn print_work(
    w: &uavgen::bench::StepWork,
    timing: &uavgen::bench::HarnessResult,
    instructions: Option<&uavgen::bench::InstructionCounts>,
    peak_gflops: Option<f64>,
) -> serde_json::Value {
    let flops = w.prepare_flops() as f64;
    println!(
        "  work per RTI step (multiply-adds of the emitted code, QP iterations not counted): prepare {} \
         (linearisation {}, condensing {}, Cholesky ≤ {}), feedback {}; {} flops in all",
        w.prepare(),
        w.linearisation,
        w.condensing,
        w.cholesky,
        w.feedback,
        w.total_flops()
    );
    let per_instruction = instructions.map(|c| flops / c.prepare[0] as f64);
    let gflops = flops / timing.prepare_ns[0];
    let fraction = peak_gflops.map(|p| gflops / p);
    let mut line = format!("  prepare: {gflops:.2} GFlop/s at its median time");
    if let (Some(f), Some(p)) = (fraction, peak_gflops) {
        line += &format!(" ({:.1} % of the {p:.1} GFlop/s peak given)", 100.0 * f);
    }
    if let Some(r) = per_instruction {
        line += &format!(", {r:.2} flops per instruction at its median instruction count");
    }
    println!("{line}");
    serde_json::json!({
        "multiply_adds": w,
        "prepare_flops": w.prepare_flops(),
        "total_flops_without_qp_iterations": w.total_flops(),
        "prepare_gflops_at_median": gflops,
        "fraction_of_peak": fraction,
        "prepare_flops_per_instruction": per_instruction,
    })
}

fn bench(args: BenchArgs) -> Result<(), String> {
    use uavgen::bench::*;
    if args.steps == 0 {
        return Err("--steps must be at least 1".into());
    }
    if let Some(path) = &args.json {
        cli::refuse_existing(path, args.force)?;
    }
    let work_dir = std::path::absolute(&args.work_dir).map_err(|e| format!("{}: {e}", args.work_dir.display()))?;
    let options = BenchOptions {
        steps: args.steps,
        seed: args.seed,
        generic_steps: args.generic_steps,
        instruction_steps: args.instructions,
        adversarial_trials: args.adversarial,
        target_cpu: if args.native {
            Some("native".into())
        } else {
            args.target_cpu.clone()
        },
        work_dir,
    };
    if let Some(p) = args.peak_gflops {
        if !(p.is_finite() && p > 0.0) {
            return Err(format!("--peak-gflops must be a positive number of GFlop/s, found {p}"));
        }
    }
    let dims = read_crate_dims(&args.crate_dir)?;
    let model = match &args.model {
        Some(p) => Some(uavgen::load(p).map_err(|e| e.to_string())?),
        None => None,
    };
    // The step's arithmetic, counted from the code generated for the crate (as `uavgen check`).
    let work = match &model {
        Some(m) => step_work(m, &args.crate_dir, &dims)?,
        None => None,
    };
    eprintln!("building the harness for {} ...", args.crate_dir.display());
    let (name, binary) =
        cli::progress::with_spinner("building the harness", || build_harness(&args.crate_dir, &options))?;
    eprintln!("running {} RTI steps on each of 3 trajectories ...", options.steps);
    let timing = cli::progress::with_spinner("timing RTI steps", || run_harness(&binary, &name, &options))?;
    let us = |ns: f64| ns / 1000.0;
    println!(
        "{name}: {} RTI steps (N = {}, {} substeps), pinned to one core: {}",
        timing.steps, dims.horizon, dims.substeps, timing.pinned
    );
    println!("  phase      median      p99    p99.9      max   [µs]");
    for (phase, q) in [
        ("prepare", timing.prepare_ns),
        ("feedback", timing.feedback_ns),
        ("total", timing.total_ns),
    ] {
        println!(
            "  {phase:<9}{:>8.1} {:>8.1} {:>8.1} {:>8.1}",
            us(q[0]),
            us(q[1]),
            us(q[2]),
            us(q[3])
        );
    }
    println!(
        "  max QP iterations {}, statuses {}, size_of::<Mpc>() = {} bytes",
        timing.max_qp_iterations, timing.statuses, timing.size_of_mpc
    );
    let instructions = if options.instruction_steps > 0 {
        eprintln!(
            "counting instructions of {} steps on each of 3 trajectories under callgrind ...",
            options.instruction_steps
        );
        let c = cli::progress::with_spinner("callgrind", || count_instructions(&binary, &options))?;
        let trajectory = ["sinusoidal", "circular", "spiral"][c.max_at.0.min(2)];
        println!(
            "  instructions per RTI step (callgrind, {} steps of the scenario): median {}, max {} ({} trajectory, step {}); \
             prepare median {}, max {}; feedback median {}, max {}",
            c.steps, c.median, c.max, trajectory, c.max_at.1, c.prepare[0], c.prepare[1], c.feedback[0], c.feedback[1]
        );
        Some(c)
    } else {
        None
    };
    let adversarial = if options.adversarial_trials > 0 {
        eprintln!(
            "counting instructions of the adversarial search ({} trials × {ADVERSARIAL_STEPS} steps) under callgrind ...",
            options.adversarial_trials
        );
        let (c, outcome) = cli::progress::with_spinner("callgrind: adversarial search", || {
            Ok::<_, String>((
                count_adversarial(&binary, &options)?,
                adversarial_outcome(&binary, &options)?,
            ))
        })?;
        let mut c = c;
        println!(
            "  adversarial search (callgrind, {} steps): median {}, max {} (trial {}, step {}); prepare median {}, max {}; \
             feedback median {}, max {}; {outcome}",
            c.steps,
            c.median,
            c.max,
            c.max_at.0,
            c.max_at.1,
            c.prepare[0],
            c.prepare[1],
            c.feedback[0],
            c.feedback[1]
        );
        c.outcome = Some(outcome);
        Some(c)
    } else {
        None
    };
    let generic =
        match (&model, options.generic_steps) {
            (Some(m), n) if n > 0 => {
                eprintln!("timing the generic reference solver ({n} steps per trajectory) ...");
                let g = cli::progress::with_spinner("generic reference solver", || {
                    run_generic(m, &dims.options, dims.horizon, dims.dt, dims.substeps, n, options.seed)
                });
                println!(
                "  generic (interpreted + clarabel): {} steps, total median {:.1} p99 {:.1} max {:.1} µs, {} failures",
                g.steps, us(g.total_ns[0]), us(g.total_ns[1]), us(g.total_ns[2]), g.failures
            );
                Some(g)
            }
            _ => None,
        };
    let flash = if args.flash {
        eprintln!("building the {FLASH_TARGET} firmware ...");
        let dir = args
            .crate_dir
            .canonicalize()
            .map_err(|e| format!("{}: {e}", args.crate_dir.display()))?;
        let s = cli::progress::with_spinner("building the firmware", || measure_flash(&dir, &name, &options))?;
        println!(
            "  {FLASH_TARGET} firmware (cortex-m7, opt-level 3, LTO): flash {} bytes (.text {}, .rodata {}, .data {}, \
             vector table {}), RAM {} bytes without the stack (.bss {}, .data {}, .uninit {})",
            s.flash(),
            s.text,
            s.rodata,
            s.data,
            s.vector_table,
            s.ram(),
            s.bss,
            s.data,
            s.uninit
        );
        Some(s)
    } else {
        None
    };
    let work_report = work.map(|w| print_work(&w, &timing, instructions.as_ref(), args.peak_gflops));
    if model.is_some() && work_report.is_none() {
        println!("  work per RTI step: counted from the emitted kernels of condensed crates only (this crate's QP is stage-wise)");
    }
    if let Some(path) = &args.json {
        let value = serde_json::json!({ "generated": timing, "instructions": instructions, "adversarial": adversarial, "generic": generic, "target_cpu": options.target_cpu, "work": work_report,
            "firmware": flash.as_ref().map(|s| serde_json::json!({ "target": FLASH_TARGET, "sections": s, "flash": s.flash(), "ram": s.ram() })) });
        let text = serde_json::to_string_pretty(&value).map_err(|e| e.to_string())? + "\n";
        cli::write_atomically(path, &text)?;
    }
    Ok(())
}
