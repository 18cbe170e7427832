//! Which of the two kinds of agent code a program is: WAA Navi's `computer` code
//! or pyautogui code ([`dialect_of`]), the one rule every caller uses (Navi's
//! reply reader on the host, both MCP servers' `run_python`).
//!
//! The rule: code that uses the `computer` (or `human`) object, a name followed by
//! a `.` outside comments and strings, is `computer` code and runs with that object
//! bound (upstream's `/execute_windows`); anything else is pyautogui code and runs
//! with `pyautogui` and `time` imported (upstream's `python -c "import pyautogui;
//! import time; ..."`). Code that does not lex is read by its text.
//!
//! It does not run or check the code: the interpreter does that.

use rustpython_parser::lexer::lex;
use rustpython_parser::{Mode, Tok};

use crate::parser::MAX_SOURCE_BYTES;

/// The kind of an agent's code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    /// WAA Navi's `computer.*` code.
    Computer,
    /// pyautogui code.
    Pyautogui,
}

/// The names whose attributes make code `computer` code.
const OBJECTS: [&str; 2] = ["computer", "human"];

/// The kind of `code` (see the module documentation).
pub fn dialect_of(code: &str) -> Dialect {
    if code.len() > MAX_SOURCE_BYTES {
        // Refused by the parser whatever it is; read by its text.
        return by_text(code);
    }
    let mut previous_names_object = false;
    for token in lex(code, Mode::Module) {
        let Ok((token, _)) = token else { return by_text(code) };
        if previous_names_object && token == Tok::Dot {
            return Dialect::Computer;
        }
        previous_names_object = matches!(&token, Tok::Name { name } if OBJECTS.contains(&name.as_str()));
    }
    Dialect::Pyautogui
}

/// The rule for code that does not lex: the text names an object's attribute.
fn by_text(code: &str) -> Dialect {
    if OBJECTS.iter().any(|object| code.contains(&format!("{object}."))) {
        Dialect::Computer
    } else {
        Dialect::Pyautogui
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn code_using_the_computer_object_is_computer_code_and_the_rest_pyautogui() {
        for (code, want) in [
            ("computer.mouse.move_id(id=3)", Dialect::Computer),
            ("x = 1\ncomputer . keyboard.write('a')", Dialect::Computer),
            ("human.ask('why')", Dialect::Computer),
            ("pyautogui.click(1, 2)", Dialect::Pyautogui),
            ("import os\nos.remove('C:/x.txt')", Dialect::Pyautogui),
            ("time.sleep(1)", Dialect::Pyautogui),
            ("# computer.mouse.single_click()\npyautogui.click()", Dialect::Pyautogui),
            ("pyautogui.write('computer.exe')", Dialect::Pyautogui),
            ("mycomputer.x = 1", Dialect::Pyautogui),
            ("computer = 3", Dialect::Pyautogui),
            ("computer.mouse.single_click(\n'unclosed", Dialect::Computer),
            ("pyautogui.write('unclosed", Dialect::Pyautogui),
        ] {
            assert_eq!(dialect_of(code), want, "{code:?}");
        }
    }
}
