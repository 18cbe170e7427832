//! The interpreter against CPython: agent-reply-like programs (loops, conditionals,
//! f-strings, comprehensions, slices, `try`, `def`, errors mid-program, syntax
//! errors) run on `arena_script` with a recording host and on `python3`
//! with stub `pyautogui` and `time` modules, and must print the same text, perform
//! the same input calls and end with the same exception type name.
//!
//! Both sides write each input call as one line (`click 100 200`, `press enter`,
//! `type hello`, `sleep 500`): the Rust side from the recorded actions, the Python
//! side from the stubs in [`PRELUDE`]. Without `python3` the CPython half prints
//! `SKIPPED: <test>: python3 not found` and returns, unless `ARENA_REQUIRE_PYTHON`
//! is set, which makes it a failure.

use std::io::Write as _;
use std::process::{Command, Stdio};

use arena_script::{run_source, ErrorKind, Globals, RecordingHost, MAX_CALL_DEPTH, MAX_STEPS};
use arena_shared::action::{Action, MouseButton};

/// Stub modules and the runner for the CPython side: it compiles the program
/// first (a syntax error runs nothing), executes it, then prints a marker, the
/// input calls and how it ended.
const PRELUDE: &str = r#"
import sys, types
calls = []
def _xy(x, y):
    return f"{int(x)} {int(y)}"
pg = types.ModuleType("pyautogui")
def click(x=None, y=None, clicks=1, interval=0.0, button="left", duration=0.0):
    calls.append(f"click {_xy(x, y)}" + ("" if button == "left" else f" {button}") + ("" if clicks == 1 else f" x{clicks}"))
def doubleClick(x=None, y=None):
    calls.append(f"doubleclick {_xy(x, y)}")
def moveTo(x=None, y=None, duration=0.0):
    calls.append(f"move {_xy(x, y)}")
def press(key, presses=1):
    calls.append(f"press {key}" + ("" if presses == 1 else f" x{presses}"))
def hotkey(*keys):
    calls.append("hotkey " + "+".join(keys))
def write(message, interval=0.0):
    calls.append("type " + message.replace("\n", "\\n"))
for _f in (click, doubleClick, moveTo, press, hotkey, write):
    setattr(pg, _f.__name__, _f)
pg.typewrite = write
tm = types.ModuleType("time")
def sleep(seconds):
    calls.append(f"sleep {round(seconds * 1000)}")
tm.sleep = sleep
sys.modules["pyautogui"] = pg
sys.modules["time"] = tm
src = sys.stdin.read()
try:
    code = compile(src, "<string>", "exec")
except SyntaxError:
    result = "SyntaxError"
else:
    try:
        exec(code, {"__name__": "__main__"})
        result = "ok"
    except Exception as e:
        result = type(e).__name__
sys.stdout.write("\n__CALLS__\n")
for c in calls:
    print(c)
print("__RESULT__ " + result)
"#;

/// How one run ended: what it printed, the input calls and `ok` or the exception name.
#[derive(Debug, PartialEq)]
struct Trace {
    stdout: String,
    calls: Vec<String>,
    result: String,
}

fn action_line(action: &Action) -> String {
    match action {
        Action::Click { x: Some(x), y: Some(y), button, count } => {
            let button = match button {
                MouseButton::Left => String::new(),
                other => format!(" {}", format!("{other:?}").to_lowercase()),
            };
            let count = if *count == 1 { String::new() } else { format!(" x{count}") };
            format!("click {x} {y}{button}{count}")
        }
        Action::DoubleClick { x: Some(x), y: Some(y) } => format!("doubleclick {x} {y}"),
        Action::MoveTo { x, y } => format!("move {x} {y}"),
        Action::KeyPress { key, presses } => {
            format!("press {key}{}", if *presses == 1 { String::new() } else { format!(" x{presses}") })
        }
        Action::Hotkey { keys } => format!("hotkey {}", keys.join("+")),
        Action::TypeText { text, .. } => format!("type {}", text.replace('\n', "\\n")),
        Action::Wait { ms } => format!("sleep {ms}"),
        other => format!("{other:?}"),
    }
}

fn ours(src: &str) -> Trace {
    let mut host = RecordingHost::new((1920, 1080), (0, 0));
    let (stdout, result) = match run_source(src, &mut host, Globals::python()) {
        Ok(out) => (out.stdout, "ok".to_owned()),
        Err(err) => {
            let name = err.kind.python_name().to_owned();
            (err.stdout, name)
        }
    };
    Trace { stdout, calls: host.actions.iter().map(action_line).collect(), result }
}

fn cpython(src: &str) -> Option<Trace> {
    let mut child = match Command::new("python3")
        .args(["-c", PRELUDE])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
    {
        Ok(child) => child,
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => return None,
        Err(err) => panic!("starting python3: {err}"),
    };
    child.stdin.take().expect("stdin").write_all(src.as_bytes()).expect("writing the program");
    let out = child.wait_with_output().expect("python3 runs");
    assert!(out.status.success(), "python3 failed: {}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).expect("UTF-8 output");
    let (stdout, rest) = text.rsplit_once("\n__CALLS__\n").expect("the marker");
    let (calls, result) = rest.rsplit_once("__RESULT__ ").expect("the result line");
    Some(Trace {
        stdout: stdout.to_owned(),
        calls: calls.lines().map(str::to_owned).collect(),
        result: result.trim_end().to_owned(),
    })
}

/// Whether `python3` runs here; without it, a counted skip (or a failure when required).
fn python_available(test: &str) -> bool {
    arena_test_support::python3_or_skip(test)
}

/// The corpus: (name, program, expected result), every program ending by printing
/// the variables whose final values matter.
const CORPUS: &[(&str, &str, &str)] = &[
    (
        "for_range_clicks",
        "import pyautogui\nfor i in range(3):\n    pyautogui.click(100 + i * 10, 200)\nprint('done', i)\n",
        "ok",
    ),
    (
        "if_elif_else_chains",
        "x = 7\nif x < 5:\n    kind = 'small'\nelif 5 <= x < 10:\n    kind = 'medium'\nelse:\n    kind = 'large'\nprint(kind, 1 < x <= 7 != 8, x == 7.0, x is not None)\n",
        "ok",
    ),
    (
        "while_break_continue",
        "n = 0\ntotal = 0\nwhile True:\n    n += 1\n    if n % 2 == 0:\n        continue\n    if n > 9:\n        break\n    total += n\nprint(n, total)\n",
        "ok",
    ),
    (
        "fstrings_with_specs",
        "x = 3.14159\nn = 42\nname = 'Bob'\nitems = [1, 2]\nprint(f\"{x:.2f} {n:05d} {name!r} {n:>6} {x*2:.1f} {'mid':^9}| {n:,} {0.256:.1%} {x:e} {x:g} {items} {len(items)=}\")\nprint(f'{n:x} {n:#o} {-n:+d} {1234567.891:,.2f} {name:*<6}')\n",
        "ok",
    ),
    (
        "percent_and_format",
        "print('%s has %d items (%.1f%%)' % ('cart', 3, 42.55))\nprint('%5s|%-5s|%03d' % ('a', 'b', 7))\nprint('{} {} {}'.format(1, 'two', 3.0))\nprint('{0}-{1}-{0} {k:>4}'.format('a', 'b', k='z'))\n",
        "ok",
    ),
    (
        "comprehensions_and_generators",
        "nums = [3, 1, 4, 1, 5, 9, 2, 6]\nevens = [n for n in nums if n % 2 == 0]\nsquares = {n: n * n for n in nums if n > 3}\nuniq = sorted({n for n in nums})\nprint(evens, squares, uniq)\nprint(sum(n for n in nums), any(n > 8 for n in nums), all(n > 0 for n in nums))\nprint([[i * j for j in range(3)] for i in range(3)], [c for row in ['ab', 'cd'] for c in row])\n",
        "ok",
    ),
    (
        "slices_and_negative_indexes",
        "a = [0, 1, 2, 3, 4, 5]\ns = 'hello world'\nprint(a[1:3], a[::-1], a[::2], a[-2:], a[:-4], a[-1], a[10:], a[4:1:-1])\nprint(s[:5], s[-5:], s[::-1], s[1:-1:3], s[-1])\nt = (1, 2, 3)\nprint(t[1:], t[::-1])\n",
        "ok",
    ),
    (
        "unpacking_and_zip",
        "a, b = 1, 2\na, b = b, a\n(c, d), e = (3, 4), 5\npairs = []\nfor i, (name, score) in enumerate(zip(['x', 'y'], [10, 20]), start=1):\n    pairs.append(f'{i}:{name}={score}')\nprint(a, b, c, d, e, pairs)\n",
        "ok",
    ),
    (
        "augmented_assignment",
        "x = 10\nx += 5\nx -= 3\nx *= 2\nx //= 5\nx %= 3\ns = 'a'\ns += 'b' * 2\nl = [1]\nl += [2, 3]\ny = 2\ny **= 10\nf = 1.5\nf /= 2\nprint(x, s, l, y, f)\n",
        "ok",
    ),
    (
        "item_assignment_and_del",
        "d = {'a': {'b': 1}, 'n': [1, 2, 3]}\nd['c'] = 3\nd['a']['b'] = 2\nd['n'][0] = 9\nd['n'].append(4)\ndel d['c']\nl = [1, 2, 3]\nl[-1] = 30\ndel l[0]\nprint(d, l)\n",
        "ok",
    ),
    (
        "big_dicts_and_sets_keep_insertion_order",
        "d = {}\nfor i in range(20000):\n    d[(i * 7919) % 20011] = i\nd[1.0] = 'one'\nd[True] = 'true'\ndel d[5]\nd[5] = 'back'\ns = set(d.values()) - {0}\nprint(len(d), list(d)[:5], list(d)[-3:], d[1], 19999 in s, len(s), sum(k for k in d if isinstance(k, int)))\n",
        "ok",
    ),
    (
        "repetition_shares_one_string",
        "x = ['a' * 10**6] * 10**6\ny = [[0] * 1000] * 1000\nprint(len(x), len(x[999999]), len(y), sum(y[0]), x[0] == x[-1])\n",
        "ok",
    ),
    (
        "copies_and_membership_in_loops",
        "x = list(range(3000))\nn = 0\nfor i in range(200):\n    s = 'a' * 3000\n    n += (-1 in x) + x.count(7) + len(s) + sum(x[:10])\nc = x.copy()\nc.append(1)\nprint(n, len(x), len(c))\n",
        "ok",
    ),
    (
        "try_except_value_error",
        "values = ['1', 'x', '3']\ngood = []\nfor v in values:\n    try:\n        good.append(int(v))\n    except ValueError as e:\n        print('bad:', e)\nprint(good)\n",
        "ok",
    ),
    (
        "try_else_finally_order",
        "def f(x):\n    try:\n        r = 10 / x\n    except ZeroDivisionError as e:\n        print('caught', type(e).__name__, e)\n        return -1\n    else:\n        print('no error')\n        return r\n    finally:\n        print('finally', x)\nprint(f(2), f(0))\n",
        "ok",
    ),
    (
        "lookup_errors_caught",
        "d = {'a': 1}\ntry:\n    d['missing']\nexcept KeyError as e:\n    print('key', e, repr(e))\ntry:\n    [1, 2][5]\nexcept (IndexError, KeyError) as e:\n    print('index', e)\ntry:\n    None.foo\nexcept AttributeError as e:\n    print('attr', e)\ntry:\n    undefined_name\nexcept NameError as e:\n    print('name', e)\ntry:\n    1 + 'a'\nexcept TypeError as e:\n    print('type', e)\n",
        "ok",
    ),
    (
        "raise_and_reraise",
        "def check(v):\n    if v < 0:\n        raise ValueError(f'negative: {v}')\n    return v\ntry:\n    try:\n        check(-1)\n    except ValueError:\n        print('inner')\n        raise\nexcept Exception as e:\n    print('outer', type(e).__name__, e, e.args)\n",
        "ok",
    ),
    (
        "defs_defaults_keywords_recursion",
        "def greet(name, greeting='Hello', punct='!'):\n    return f'{greeting}, {name}{punct}'\ndef fact(n):\n    return 1 if n <= 1 else n * fact(n - 1)\nprint(greet('Ann'), greet('Bo', punct='?'), greet(greeting='Hi', name='Cy'))\nprint(fact(10), fact(20))\n",
        "ok",
    ),
    (
        "lambdas_sorting_and_closures",
        "people = [('ann', 31), ('bob', 25), ('cy', 31), ('di', 22)]\nby_age = sorted(people, key=lambda p: p[1])\nby_age_desc = sorted(people, key=lambda p: p[1], reverse=True)\ndef adder(n):\n    return lambda x: x + n\nadd5 = adder(5)\nprint(by_age, by_age_desc, add5(10), list(map(lambda x: x * 2, [1, 2])), list(filter(None, [0, 1, '', 'a'])))\n",
        "ok",
    ),
    (
        "str_methods",
        "s = '  Hello, World  '\nt = s.strip()\nprint(t.lower(), t.upper(), t.split(', '), '-'.join(['a', 'b']), t.replace('World', 'There'))\nprint(t.startswith('Hell'), t.endswith(('x', 'd')), t.find('o'), t.rfind('o'), t.count('l'), 'abc def'.title())\nprint('123'.isdigit(), 'a1'.isalnum(), 'ab'.isalpha(), '7'.zfill(3), 'ab'.center(6, '*'), 'x'.ljust(3) + '|', 'a,b,c'.split(',', 1), 'k=v'.partition('='))\nprint(s.lstrip() + '|', s.rstrip() + '|', 'a b  c'.split(), 'line1\\nline2'.splitlines(), 'Hi'.capitalize(), 'ab'.upper().lower())\n",
        "ok",
    ),
    (
        "list_methods",
        "l = [3, 1, 2]\nl.append(5)\nl.extend([7, 0])\nl.insert(1, 9)\nlast = l.pop()\nfirst = l.pop(0)\nl.remove(9)\nl.sort()\ncopy = l.copy()\nl.reverse()\nprint(l, copy, last, first, l.index(5), l.count(1), len(l))\n",
        "ok",
    ),
    (
        "dict_methods",
        "d = {'b': 2, 'a': 1}\nd.update({'c': 3}, d=4)\nv = d.pop('a')\nw = d.setdefault('e', 5)\nprint(d.get('b'), d.get('zz', 'none'), list(d.keys()), list(d.values()), list(d.items()), v, w, 'c' in d, len(d))\nfor k, val in sorted(d.items(), key=lambda kv: -kv[1]):\n    print(k, val)\n",
        "ok",
    ),
    (
        "builtins_mix",
        "nums = [4, -2, 7, 1]\nprint(min(nums), max(nums), max(nums, key=abs), min(['bb', 'a', 'ccc'], key=len), sorted(nums, reverse=True), list(reversed(nums)))\nprint(abs(-3.5), round(2.5), round(3.14159, 2), sum(nums), len('héllo'), isinstance(3, int), isinstance(True, int), isinstance('s', (int, str)))\nprint(divmod(17, 5), pow(2, 8), hex(255), bin(5), int('ff', 16), float('2.5'), str(12) + '!', bool([]), list(range(10, 0, -3)), tuple('ab'), dict(a=1))\n",
        "ok",
    ),
    (
        "agent_types_lines",
        "import pyautogui\nimport time\nlines = ['first line', 'second line']\nfor line in lines:\n    pyautogui.write(line)\n    pyautogui.press('enter')\n    time.sleep(0.5)\npyautogui.hotkey('ctrl', 's')\nprint(f'typed {len(lines)} lines')\n",
        "ok",
    ),
    (
        "agent_grid_with_conditions",
        "import pyautogui\ncells = [(r, c) for r in range(2) for c in range(3)]\nclicked = 0\nfor r, c in cells:\n    if (r + c) % 2:\n        continue\n    pyautogui.click(x=50 + c * 100, y=40 + r * 30)\n    clicked += 1\npyautogui.doubleClick(10, 10)\npyautogui.moveTo(5, 6)\nprint(clicked)\n",
        "ok",
    ),
    (
        "runtime_error_mid_program",
        "import pyautogui\nprint('start')\npyautogui.click(1, 2)\nvalue = undefined_variable + 1\npyautogui.click(3, 4)\nprint('never')\n",
        "NameError",
    ),
    (
        "type_error_in_loop",
        "total = 0\nfor x in [1, 2, 'three', 4]:\n    print('adding', x)\n    total += x\nprint(total)\n",
        "TypeError",
    ),
    (
        "uncaught_user_exception",
        "import pyautogui\npyautogui.press('tab')\ndef validate(n):\n    if n > 3:\n        raise ValueError('too big')\n    return n\nfor i in range(10):\n    print(validate(i))\n",
        "ValueError",
    ),
    (
        "zero_division_uncaught",
        "rates = [2, 1, 0]\nfor r in rates:\n    print(10 // r, 10 % r)\n",
        "ZeroDivisionError",
    ),
    (
        "syntax_error_runs_nothing",
        "import pyautogui\nprint('before')\npyautogui.click(1, 2)\nfor i in range(3)\n    pyautogui.click(i, i)\n",
        "SyntaxError",
    ),
    (
        "syntax_error_unclosed_bracket",
        "import pyautogui\npyautogui.click(1, 2)\nx = [1, 2,\nprint(x)\n",
        "SyntaxError",
    ),
    (
        "global_and_nested_functions",
        "count = 0\ndef bump(step=1):\n    global count\n    count += step\n    return count\ndef twice(f):\n    f()\n    return f(step=10)\nprint(twice(bump), count)\ndef outer(base):\n    def add(x):\n        return base + x\n    return [add(1), add(2)]\nprint(outer(10))\n",
        "ok",
    ),
    (
        "boolean_logic_and_membership",
        "a = None\nb = 'text'\nprint(a or 'default', b and len(b), not a, a is None, b is not None)\nprint('ex' in b, 'zz' not in b, 2 in [1, 2], 'k' in {'k': 1}, 3 in range(5), 5 in range(0, 10, 2))\nprint('yes' if b else 'no', 0 or [] or 'last', 1 and 2 and 3, [] == [], (1, 2) < (1, 3), 'abc' < 'abd')\n",
        "ok",
    ),
    (
        "loop_else_clauses",
        "for n in [2, 3, 4]:\n    if n > 5:\n        break\nelse:\n    print('no break', n)\ni = 0\nwhile i < 3:\n    i += 1\nelse:\n    print('while done', i)\nfor n in [1, 8]:\n    if n > 5:\n        print('found', n)\n        break\nelse:\n    print('not printed')\n",
        "ok",
    ),
    (
        "main_guard_and_assert",
        "def main():\n    steps = ['open', 'type', 'save']\n    for i, step in enumerate(steps):\n        print(f'{i + 1}. {step}')\n    assert len(steps) == 3, 'three steps'\n    return len(steps)\nif __name__ == '__main__':\n    print(main())\nassert False, 'stop here'\n",
        "AssertionError",
    ),
    (
        "numbers_print_like_python",
        "print(1 / 3, 2 ** 10, 7 // 2, -7 // 2, 10 % -3, 0.1 + 0.2, 1e-5, 1e16, 3.0, -0.5 * 2, 2 ** -1, 7 / 7)\nprint(int(3.9), int(-3.9), round(-2.5), round(0.125, 2), float('inf'), 10 ** 18, 5 & 3, 5 | 3, 5 ^ 3, 1 << 10, -16 >> 2, ~5)\n",
        "ok",
    ),
    (
        "sets_and_dict_merges",
        "a = {3, 1, 2}\nb = {2, 3, 4}\na.add(10)\na.discard(1)\nprint(sorted(a | b), sorted(a & b), sorted(a - b), len(a), 10 in a, {1, 2} == {2, 1})\nd = {'x': 1} | {'y': 2}\nprint(d, dict(zip('ab', [1, 2])), dict([('k', 'v')]))\n",
        "ok",
    ),
    (
        "word_count_and_ranking",
        "text = 'the cat and the hat and the bat'\ncounts = {}\nfor w in text.split():\n    counts[w] = counts.get(w, 0) + 1\nranked = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))\nfor word, n in ranked[:3]:\n    print(f'{word:<5}{n:>3}')\nprint(max(counts, key=counts.get), len(counts))\n",
        "ok",
    ),
    (
        "retry_loop_with_sleep",
        "import pyautogui, time\nattempts = 0\nwhile attempts < 5:\n    attempts += 1\n    pyautogui.press('f5')\n    time.sleep(0.25)\n    if attempts * 2 >= 6:\n        break\nprint('attempts', attempts)\n",
        "ok",
    ),
    (
        "finally_and_return_values",
        "def f():\n    try:\n        return 'try'\n    finally:\n        print('cleanup')\ndef g(items):\n    result = []\n    for i, x in enumerate(items):\n        try:\n            result.append(10 // x)\n        except ZeroDivisionError:\n            result.append(None)\n            continue\n        finally:\n            result.append(i)\n    return result\nprint(f(), g([5, 0, 2]))\n",
        "ok",
    ),
    (
        "formatting_extras",
        "vals = [3.14159, 2.0, 1234.5]\nfor v in vals:\n    print('|{:>10.3f}|{:<8.1e}|{:^9g}|'.format(v, v, v))\nprint('%-6s|%6.2f|%x|%c' % ('ab', 3.14159, 255, 65), str(1.0), str(10 / 4), repr('q'), f'{3!s:>3}', f\"{'x' * 3}\")\n",
        "ok",
    ),
];

#[test]
fn corpus_matches_cpython() {
    if !python_available("corpus_matches_cpython") {
        return;
    }
    let mut mismatches = Vec::new();
    for (name, src, expected) in CORPUS {
        let ours = ours(src);
        let theirs = cpython(src).expect("python3 runs");
        assert_eq!(theirs.result, *expected, "{name}: CPython's result; the corpus expectation is wrong");
        if ours != theirs {
            mismatches.push(format!("{name}:\n  ours:    {ours:?}\n  CPython: {theirs:?}"));
        }
    }
    println!("{} of {} corpus programs match CPython", CORPUS.len() - mismatches.len(), CORPUS.len());
    assert!(mismatches.is_empty(), "{} mismatches:\n{}", mismatches.len(), mismatches.join("\n"));
}

/// The corpus's own expectations hold on our side even without `python3`.
#[test]
fn corpus_results_on_our_interpreter() {
    for (name, src, expected) in CORPUS {
        assert_eq!(ours(src).result, *expected, "{name}");
    }
    let syntax = ours("import pyautogui\nprint('before')\npyautogui.click(1, 2)\nfor i in range(3)\n    pass\n");
    assert_eq!(syntax, Trace { stdout: String::new(), calls: Vec::new(), result: "SyntaxError".into() });
    let mid = ours("import pyautogui\nprint('start')\npyautogui.click(1, 2)\nvalue = undefined_variable + 1\n");
    assert_eq!(mid, Trace { stdout: "start\n".into(), calls: vec!["click 1 2".into()], result: "NameError".into() });
}

#[test]
fn loops_stop_at_the_step_budget_and_except_does_not_hide_it() {
    let mut host = RecordingHost::new((100, 100), (0, 0));
    let src = "import pyautogui\npyautogui.press('a')\nn = 0\ntry:\n    while True:\n        n += 1\nexcept Exception:\n    print('caught')\nprint('after')\n";
    let err = run_source(src, &mut host, Globals::python()).unwrap_err();
    assert_eq!(err.kind, ErrorKind::LoopLimit);
    assert_eq!(err.line, 5, "{err}");
    assert!(err.message.contains(&MAX_STEPS.to_string()), "{err}");
    assert_eq!(err.stdout, "");
    assert_eq!(host.actions.len(), 1, "the press before the loop stays done");
    let src = "total = 0\nfor i in range(10 ** 12):\n    total += i\n";
    let err = run_source(src, &mut host, Globals::python()).unwrap_err();
    assert_eq!(err.kind, ErrorKind::LoopLimit, "{err}");
    let err = run_source("x = [i for i in range(10 ** 9)]", &mut host, Globals::python()).unwrap_err();
    assert_eq!(err.kind, ErrorKind::LoopLimit, "{err}");
}

#[test]
fn recursion_stops_at_the_call_depth() {
    let mut host = RecordingHost::new((100, 100), (0, 0));
    let src = "def down(n):\n    return down(n + 1)\ntry:\n    down(0)\nexcept Exception:\n    print('caught')\n";
    let err = run_source(src, &mut host, Globals::python()).unwrap_err();
    assert_eq!(err.kind, ErrorKind::Recursion, "{err}");
    assert!(err.message.contains(&MAX_CALL_DEPTH.to_string()), "{err}");
    // Just under the limit runs, on a test thread's stack.
    let src =
        format!("def down(n):\n    return n if n == 0 else 1 + down(n - 1)\nprint(down({}))\n", MAX_CALL_DEPTH - 1);
    let out = run_source(&src, &mut host, Globals::python()).unwrap();
    assert_eq!(out.stdout, format!("{}\n", MAX_CALL_DEPTH - 1));
    // Deep expressions in every call stop with the same error, never by overflowing the stack.
    let deep = format!("{}down(n - 1){}", "1 + (".repeat(20), ")".repeat(20));
    let src = format!("def down(n):\n    return n if n == 0 else {deep}\nprint(down({}))\n", MAX_CALL_DEPTH - 1);
    let err = run_source(&src, &mut host, Globals::python()).unwrap_err();
    assert_eq!(err.kind, ErrorKind::Recursion, "{err}");
}

#[test]
fn unsupported_code_is_not_swallowed_by_except() {
    let mut host = RecordingHost::new((100, 100), (0, 0));
    let src = "import pyautogui\ntry:\n    pyautogui.locateOnScreen('a.png')\nexcept Exception:\n    print('caught')\n";
    let err = run_source(src, &mut host, Globals::python()).unwrap_err();
    assert_eq!(err.kind, ErrorKind::Attribute, "{err}");
    assert_eq!(err.stdout, "");
    let err =
        run_source("try:\n    open('x')\nexcept Exception:\n    pass\n", &mut host, Globals::python()).unwrap_err();
    assert_eq!(err.kind, ErrorKind::NotSupported, "{err}");
}
