//! Getters of upstream's `getters/general.py` and `getters/misc.py`: `rule`
//! (the task's own rules) and `vm_command_line` (a program's output).

use arena_script::CommandArg;
use arena_shared::cmdline::{execute_command, CommandSpec};
use arena_shared::exec::ExecRequest;
use serde_json::Value;

use super::{GetterError, Params};
use crate::value::{json_kind, Fetched};
use crate::EvalContext;

/// `get_rule`: returns `rules` as written.
pub(super) fn rule(params: &Params<'_>) -> Result<Fetched, GetterError> {
    Ok(Fetched::Json(params.get("rules")?.clone()))
}

/// `get_vm_command_line`: runs `command` in the guest and returns its
/// standard output. A program that fails still has output (upstream's
/// `/execute` answers 200 with `output`); a guest error (no such program,
/// a lost connection) is an error here, where upstream returns `None`, so
/// the reason is recorded.
pub(super) async fn vm_command_line(ctx: &EvalContext, params: &Params<'_>) -> Result<Fetched, GetterError> {
    let request = ExecRequest::new(command_spec(params)?);
    let result = ctx.client.exec(&request).await.map_err(|err| params.guest(err))?;
    if result.timed_out {
        return Err(params.failed(format!("the command was killed after {} ms", result.duration_ms)));
    }
    Ok(Fetched::Text(result.stdout))
}

/// The command upstream's `/execute` would run (see
/// [`arena_shared::cmdline::execute_command`]): a list as is; a string split like
/// `shlex.split` (POSIX); with `shell`, one line for `cmd /c` (a list joined as
/// `subprocess.list2cmdline` does).
pub(super) fn command_spec(params: &Params<'_>) -> Result<CommandSpec, GetterError> {
    let shell = params.truthy("shell");
    let command = match params.get("command")? {
        Value::String(line) => CommandArg::Line(line.clone()),
        Value::Array(items) => CommandArg::Args(
            items
                .iter()
                .enumerate()
                .map(|(idx, v)| {
                    v.as_str()
                        .map(str::to_owned)
                        .ok_or_else(|| params.bad(format!("`command[{idx}]` must be a string")))
                })
                .collect::<Result<Vec<_>, _>>()?,
        ),
        other => return Err(params.bad(format!("`command` must be a string or a list, not {}", json_kind(other)))),
    };
    let spec =
        execute_command(&command, shell, None).map_err(|err| params.bad(format!("`command` does not split: {err}")))?;
    let empty = match &spec {
        CommandSpec::Shell(line) => line.is_empty(),
        CommandSpec::Argv(argv) => argv.first().is_none_or(String::is_empty),
    };
    if empty {
        return Err(params.bad("`command` is empty"));
    }
    Ok(spec)
}
