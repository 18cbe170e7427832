//! Getters of upstream's `getters/general.py` and `getters/misc.py`: `rule`
//! (the task's own rules) and `vm_command_line` (a program's output).

use arena_guest::cmdline::{list2cmdline, shlex_split};
use arena_shared::exec::ExecRequest;
use serde_json::Value;

use super::{GetterError, Params};
use crate::eval::value::{json_kind, Fetched};
use crate::eval::EvalContext;

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
    let argv = command_argv(params)?;
    let request = ExecRequest { argv, timeout_ms: None, max_output_bytes: None, cwd: None, stdin: None };
    let result = ctx.client.exec(&request).await.map_err(|err| params.guest(err))?;
    if result.timed_out {
        return Err(params.failed(format!("the command was killed after {} ms", result.duration_ms)));
    }
    Ok(Fetched::Text(result.stdout))
}

/// The argument vector upstream's `/execute` would run: a list as is; a string
/// split like `shlex.split` (POSIX); with `shell`, the line handed to `cmd /c`
/// (a list joined as `subprocess.list2cmdline` does).
pub(super) fn command_argv(params: &Params<'_>) -> Result<Vec<String>, GetterError> {
    let shell = params.truthy("shell");
    let command = params.get("command")?;
    let argv = match command {
        Value::String(line) if shell => vec!["cmd".into(), "/c".into(), line.clone()],
        Value::String(line) => {
            shlex_split(line).map_err(|err| params.bad(format!("`command` does not split: {err}")))?
        }
        Value::Array(items) => {
            let words = items
                .iter()
                .enumerate()
                .map(|(idx, v)| {
                    v.as_str()
                        .map(str::to_owned)
                        .ok_or_else(|| params.bad(format!("`command[{idx}]` must be a string")))
                })
                .collect::<Result<Vec<_>, _>>()?;
            if shell {
                vec!["cmd".into(), "/c".into(), list2cmdline(&words)]
            } else {
                words
            }
        }
        other => return Err(params.bad(format!("`command` must be a string or a list, not {}", json_kind(other)))),
    };
    if argv.first().is_none_or(String::is_empty) {
        return Err(params.bad("`command` is empty"));
    }
    Ok(argv)
}
