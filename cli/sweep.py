"""``cutkit sweep``: run a parameter study of many simulations on Dask."""

import click

from cutkit.cli._ui import overwrite_option


@click.command(name="sweep")
@click.argument("spec", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Output folder: results.parquet, results.csv, runs/<key>/.")
@click.option("--scheduler", metavar="tcp://HOST:8786",
              help="Use this running Dask scheduler (default: an embedded local cluster).")
@click.option("--workers", "n_workers", type=int, default=None,
              help="Worker processes of the embedded cluster (default: one per core).")
@click.option("--resume", is_flag=True, help="Skip every run that already has a result in the output folder.")
@overwrite_option
@click.option("--retry-failed", is_flag=True, help="With --resume, run the failed runs again.")
def command(spec, out_dir, scheduler, n_workers, resume, overwrite, retry_failed):
    """Run every simulation of the sweep SPEC (TOML, see docs/sweep.md) and tabulate the results."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from cutkit.cli._ui import console, esc, folder_guard, say
    from cutkit.errors import InputError
    from cutkit.io.atomic import check_output_folder, check_writable, clear_outputs
    from cutkit.sweep import load_spec, run_sweep

    if resume and overwrite:
        raise InputError("--resume continues the earlier sweep, --overwrite replaces it; give one")
    if retry_failed and not resume:
        raise InputError("--retry-failed needs --resume")
    if resume:
        check_writable(out_dir, folder=True)
        earlier = []
    else:
        earlier = check_output_folder(out_dir, "sweep", overwrite, inputs=(spec,))
    sweep = load_spec(spec)
    clear_outputs(earlier)
    bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                   TextColumn("failed {task.fields[failed]}"), TextColumn("ETA"), TimeRemainingColumn(),
                   console=console, transient=False)
    state = {}

    def on_event(kind, info):
        if kind == "start":
            say(f"{sweep.name}: {info['total']} runs, {info['skipped']} with results already, "
                f"{info['todo']} to run on {info['workers']} worker{'s' if info['workers'] != 1 else ''}")
            state["task"] = bar.add_task("sweep", total=info["todo"], failed=0)
        else:
            bar.update(state["task"], completed=info["done"], failed=info["failed"])
            row = info["row"]
            if row["status"] != "ok":
                bar.console.print(f"[yellow]failed[/yellow] {esc(row['key'])}: {esc(row['error'])}")

    with folder_guard(out_dir), bar:
        report = run_sweep(sweep, out_dir, scheduler=scheduler, n_workers=n_workers, resume=resume,
                           retry_failed=retry_failed, on_event=on_event)
    rate = report.ran / report.wall_s * 3600 if report.wall_s > 0 and report.ran else 0.0
    say(f"{report.ran} runs in {report.wall_s:.1f} s ({rate:.0f} runs per hour), {report.failed} failed, "
        f"{report.skipped} skipped; results in {out_dir}/results.parquet and {out_dir}/results.csv")
    return 0
