//! The shader composer: WGSL modules with explicit imports and declared parameters, assembled
//! into one shader per pipeline variant.
//!
//! WGSL has no `#include`. Every file under `shaders/` (folders mirror `src/`) is a module named
//! by its path without the extension (`trace/ao`), and may start with directives, each a whole
//! line:
//! - `#import trace/common`: the module needs another one; it is included once per composed
//!   shader, before the modules that import it, however many import it.
//! - `enable wgpu_ray_query;` (any WGSL `enable` directive): moved to the top of the composed
//!   shader, once, since WGSL allows directives only before every declaration and an imported
//!   module's declarations come first.
//! - `#param OUTPUT0_FORMAT`: the module has a parameter, written `{{OUTPUT0_FORMAT}}` in its
//!   text, that every composition including it must give (a bind group number, a texel format, a
//!   constant). A parameter is one token; where variants differ in code, they are different
//!   modules the pass chooses between (e.g. `denoise/output/none` or `denoise/output/one`).
//!
//! [`ShaderLibrary::compose`] refuses, with a [`ComposeError`] naming the module, an unknown
//! import, an import cycle, a placeholder the module does not declare, a declared parameter not
//! given, and a given parameter no included module declares (a misspelt name). Every variant the
//! SDK creates is composed and validated with naga by a CPU-only test of its pass module, so these
//! errors are programming errors that `cargo test` catches; [`compose`] panics on them.

use std::borrow::Cow;
use std::collections::BTreeMap;

/// Why a shader could not be composed ([`compose_shader`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ComposeError {
    /// A root or an import names no module of the library.
    #[error("no shader module `{module}` (imported by `{by}`)")]
    UnknownModule {
        /// The missing module.
        module: String,
        /// The module importing it, or `<roots>`.
        by: String,
    },
    /// Modules import each other in a loop.
    #[error("shader modules import each other in a loop: {}", cycle.join(" -> "))]
    ImportCycle {
        /// The modules of the loop, the first repeated at the end.
        cycle: Vec<String>,
    },
    /// A directive line is not `#import <module>` or `#param <NAME>`.
    #[error("shader module `{module}`, line {line}: bad directive `{text}`")]
    BadDirective {
        /// The module.
        module: String,
        /// 1-based line number.
        line: usize,
        /// The line.
        text: String,
    },
    /// A `{{NAME}}` placeholder the module does not declare with `#param NAME`.
    #[error("shader module `{module}` uses `{{{{{name}}}}}` without `#param {name}`")]
    UndeclaredPlaceholder {
        /// The module.
        module: String,
        /// The placeholder's name.
        name: String,
    },
    /// A parameter an included module declares was not given.
    #[error("shader module `{module}` needs the parameter {name}")]
    MissingParameter {
        /// The module declaring it.
        module: String,
        /// The parameter.
        name: String,
    },
    /// A parameter was given that no included module declares.
    #[error("parameter {name} is declared by none of the composed modules ({})", modules.join(", "))]
    UnusedParameter {
        /// The parameter.
        name: String,
        /// The modules composed.
        modules: Vec<String>,
    },
}

/// A set of WGSL modules by name.
#[derive(Debug, Clone)]
pub(crate) struct ShaderLibrary {
    modules: BTreeMap<&'static str, Cow<'static, str>>,
    /// Modules whose text is another module's ([`ShaderLibrary::substitute`]): the composed
    /// shader's module header names the module the text came from.
    substitutes: BTreeMap<&'static str, String>,
}

impl ShaderLibrary {
    /// The SDK's own modules (every file under `shaders/`).
    pub fn builtin() -> Self {
        ShaderLibrary {
            modules: super::shader_files::MODULES
                .iter()
                .map(|&(name, source)| (name, Cow::Borrowed(source)))
                .collect(),
            substitutes: BTreeMap::new(),
        }
    }

    /// Gives module `name` the text of module `with` (which must exist): every import of
    /// `name` gets `with`'s code. How a traversal backend stands in for another
    /// (`scene/traversal`: see the scene's traversal module).
    ///
    /// # Panics
    ///
    /// When there is no module `with`: the names are the SDK's own constants, so a test of any
    /// pass composed this way catches it.
    pub fn substitute(&mut self, name: &'static str, with: &str) {
        let text = self
            .modules
            .get(with)
            .cloned()
            .unwrap_or_else(|| panic!("no shader module `{with}` to stand in for `{name}`"));
        self.modules.insert(name, text);
        self.substitutes.insert(name, with.to_string());
    }

    /// Replaces (or adds) module `name`: tests stand a simple module in for a real one with the
    /// same interface (e.g. a lighting cache that returns known colours).
    #[cfg_attr(not(test), allow(dead_code))]
    pub fn replace(&mut self, name: &'static str, source: impl Into<Cow<'static, str>>) {
        self.modules.insert(name, source.into());
    }

    /// The names of every module.
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.modules.keys().copied()
    }

    /// One WGSL shader of the modules `roots` and everything they import (each module once,
    /// imports before importers, roots in the order given), with `params` filled in.
    pub fn compose(&self, roots: &[&str], params: &[(&str, &str)]) -> Result<String, ComposeError> {
        let mut order = Vec::new();
        for &root in roots {
            self.visit(root, "<roots>", &mut Vec::new(), &mut order)?;
        }
        let mut declared = Vec::new();
        let mut enables: Vec<String> = Vec::new();
        let mut text = String::new();
        for &name in &order {
            let module = self.parse(name)?;
            if let Some(missing) = module
                .params
                .iter()
                .find(|p| !params.iter().any(|(n, _)| n == *p))
            {
                return Err(ComposeError::MissingParameter {
                    module: name.to_string(),
                    name: missing.to_string(),
                });
            }
            declared.extend_from_slice(&module.params);
            for e in &module.enables {
                if !enables.contains(e) {
                    enables.push(e.clone());
                }
            }
            let from = self.substitutes.get(name).map_or(name, String::as_str);
            text.push_str(&module_header(from));
            text.push_str(&module.fill(name, params)?);
        }
        if let Some(&(unused, _)) = params.iter().find(|(n, _)| !declared.contains(n)) {
            return Err(ComposeError::UnusedParameter {
                name: unused.to_string(),
                modules: order.iter().map(|m| m.to_string()).collect(),
            });
        }
        if enables.is_empty() {
            return Ok(text);
        }
        let mut with_directives: String = enables.iter().map(|e| format!("{e}\n")).collect();
        with_directives.push_str(&text);
        Ok(with_directives)
    }

    /// Depth-first visit of `name`'s imports; appends each module after its imports.
    fn visit(
        &self,
        name: &str,
        by: &str,
        path: &mut Vec<&'static str>,
        order: &mut Vec<&'static str>,
    ) -> Result<(), ComposeError> {
        let Some((&key, _)) = self.modules.get_key_value(name) else {
            return Err(ComposeError::UnknownModule {
                module: name.to_string(),
                by: by.to_string(),
            });
        };
        if order.contains(&key) {
            return Ok(());
        }
        if let Some(start) = path.iter().position(|&m| m == key) {
            let mut cycle: Vec<String> = path[start..].iter().map(|m| m.to_string()).collect();
            cycle.push(key.to_string());
            return Err(ComposeError::ImportCycle { cycle });
        }
        path.push(key);
        for import in self.parse(key)?.imports {
            self.visit(import, key, path, order)?;
        }
        path.pop();
        order.push(key);
        Ok(())
    }

    /// The directives and body of module `name` (which exists).
    fn parse(&self, name: &str) -> Result<Module<'_>, ComposeError> {
        let source = self.modules.get(name).map(|s| s.as_ref()).unwrap_or("");
        let mut module = Module {
            imports: Vec::new(),
            params: Vec::new(),
            enables: Vec::new(),
            body: String::with_capacity(source.len()),
        };
        for (i, line) in source.lines().enumerate() {
            let trimmed = line.trim();
            if trimmed.starts_with("enable ") && trimmed.ends_with(';') {
                module.enables.push(trimmed.to_string());
                module.body.push('\n');
                continue;
            }
            if !trimmed.starts_with('#') {
                module.body.push_str(line);
                module.body.push('\n');
                continue;
            }
            let bad = || ComposeError::BadDirective {
                module: name.to_string(),
                line: i + 1,
                text: line.to_string(),
            };
            let mut words = trimmed.split_whitespace();
            let (Some(directive), Some(arg), None) = (words.next(), words.next(), words.next())
            else {
                return Err(bad());
            };
            match directive {
                "#import" => module.imports.push(arg),
                "#param" if is_identifier(arg) => module.params.push(arg),
                _ => return Err(bad()),
            }
            // Keep the line count, so naga's line numbers stay close to the file's.
            module.body.push('\n');
        }
        Ok(module)
    }
}

/// A module split into its directives and its WGSL.
struct Module<'a> {
    imports: Vec<&'a str>,
    params: Vec<&'a str>,
    /// Its `enable` directives (hoisted to the top of the composed shader).
    enables: Vec<String>,
    body: String,
}

impl Module<'_> {
    /// The body of module `name` with every `{{NAME}}` replaced by its value in `params` (which
    /// holds every declared parameter); a placeholder the module does not declare is refused.
    fn fill(&self, name: &str, params: &[(&str, &str)]) -> Result<String, ComposeError> {
        let mut out = String::with_capacity(self.body.len());
        let mut rest = self.body.as_str();
        while let Some(start) = rest.find("{{") {
            out.push_str(&rest[..start]);
            let after = &rest[start + 2..];
            let end = after.find("}}").unwrap_or(after.len());
            let placeholder = &after[..end];
            let value = params
                .iter()
                .rev()
                .find(|(n, _)| *n == placeholder)
                .map(|&(_, v)| v)
                .filter(|_| self.params.contains(&placeholder));
            let Some(value) = value else {
                return Err(ComposeError::UndeclaredPlaceholder {
                    module: name.to_string(),
                    name: placeholder.to_string(),
                });
            };
            out.push_str(value);
            rest = &after[(end + 2).min(after.len())..];
        }
        out.push_str(rest);
        Ok(out)
    }
}

/// The comment line that starts module `name` in a composed shader (where naga's messages and a
/// reader find which module a line came from).
pub(crate) fn module_header(name: &str) -> String {
    format!("// ---- module {name} ----\n")
}

/// Whether `s` is a parameter name: ASCII letters, digits and `_`, not starting with a digit.
fn is_identifier(s: &str) -> bool {
    s.chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The names of the SDK's WGSL modules (each file under the crate's `shaders/` folder, by its path
/// without `.wgsl`, e.g. `trace/ao`), for tools that inspect or compile the SDK's shaders outside
/// it (driver statistics, browser checks).
pub fn shader_modules() -> Vec<&'static str> {
    ShaderLibrary::builtin().names().collect()
}

/// One WGSL shader made of the SDK's modules `roots` and every module they import (each once,
/// imports first), with the modules' declared parameters given in `params` (`{{NAME}}` in a
/// module's text; see the `#param` lines at the top of each module). This is how the SDK makes
/// each of its pipelines; tools use it to compile the same text.
///
/// ```
/// let wgsl = kickstart_rt::compose_shader(&["trace/rays"], &[]).unwrap();
/// assert!(wgsl.contains("fn main"));
/// assert!(kickstart_rt::compose_shader(&["trace/ao"], &[]).is_err()); // needs its parameters
/// ```
pub fn compose_shader(roots: &[&str], params: &[(&str, &str)]) -> Result<String, ComposeError> {
    ShaderLibrary::builtin().compose(roots, params)
}

/// The composed shader of the SDK's modules `roots` with `params` (see
/// [`ShaderLibrary::compose`]).
///
/// # Panics
///
/// On a [`ComposeError`]: the roots and parameters are the SDK's own, fixed per variant, and every
/// variant is composed by a CPU-only test, so an error here is a programming error.
pub(crate) fn compose(roots: &[&str], params: &[(&str, &str)]) -> String {
    ShaderLibrary::builtin()
        .compose(roots, params)
        .unwrap_or_else(|e| panic!("composing {roots:?}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn library(modules: &[(&'static str, &'static str)]) -> ShaderLibrary {
        let mut l = ShaderLibrary {
            modules: BTreeMap::new(),
            substitutes: BTreeMap::new(),
        };
        for &(name, source) in modules {
            l.replace(name, source);
        }
        l
    }

    const MODULES: &[(&str, &str)] = &[
        ("a/types", "struct T { x: u32 }"),
        (
            "a/util",
            "#import a/types\nfn util(t: T) -> u32 { return t.x; }",
        ),
        (
            "b/pass",
            "#import a/util\n#import a/types\n#param GROUP\n#param FORMAT\n\
             @group({{GROUP}}) @binding(0) var out: texture_storage_2d<{{FORMAT}}, write>;",
        ),
        ("b/other", "#import a/util\nfn other() {}"),
    ];

    #[test]
    fn imports_come_first_once_each_and_parameters_are_filled() {
        let s = library(MODULES)
            .compose(
                &["b/pass", "b/other"],
                &[("GROUP", "2"), ("FORMAT", "rgba8unorm")],
            )
            .unwrap();
        let at = |needle: &str| {
            assert_eq!(s.matches(needle).count(), 1, "{needle} once in\n{s}");
            s.find(needle).unwrap()
        };
        assert!(at("struct T") < at("fn util") && at("fn util") < at("@group(2) @binding(0)"));
        assert!(at("texture_storage_2d<rgba8unorm, write>") < at("fn other"));
        assert!(!s.contains("#import") && !s.contains("{{"), "{s}");
        // Directive lines stay as empty lines, so a module's line numbers are kept.
        let pass = s.split("// ---- module b/pass ----\n").nth(1).unwrap();
        assert_eq!(pass.lines().position(|l| l.starts_with("@group")), Some(4));
    }

    /// An `enable` directive of an imported module opens the composed shader, once, however many
    /// modules declare it; a substituted module's code and header are its stand-in's.
    #[test]
    fn enables_come_first_and_substitutes_stand_in() {
        let mut l = library(&[
            ("a/base", "struct B { x: u32 }\n"),
            (
                "a/trace",
                "#import a/base\nfn trace() -> u32 { return 1u; }\n",
            ),
            (
                "a/trace_hw",
                "enable wgpu_ray_query;\n#import a/base\nfn trace() -> u32 { return 2u; }\n",
            ),
            (
                "a/pass",
                "enable wgpu_ray_query;\n#import a/trace\nfn main() {}\n",
            ),
        ]);
        let plain = l.compose(&["a/pass"], &[]).unwrap();
        assert!(
            plain.starts_with("enable wgpu_ray_query;\n// ---- module a/base"),
            "{plain}"
        );
        assert!(plain.contains("return 1u;"), "{plain}");
        l.substitute("a/trace", "a/trace_hw");
        let hw = l.compose(&["a/pass"], &[]).unwrap();
        assert_eq!(hw.matches("enable wgpu_ray_query;").count(), 1, "{hw}");
        assert!(hw.starts_with("enable wgpu_ray_query;\n"), "{hw}");
        assert!(
            hw.contains("return 2u;") && !hw.contains("return 1u;"),
            "{hw}"
        );
        assert!(hw.contains(&module_header("a/trace_hw")), "{hw}");
    }

    #[test]
    fn every_mistake_is_named() {
        let l = library(MODULES);
        let params = [("GROUP", "1"), ("FORMAT", "r32float")];
        assert_eq!(
            l.compose(&["b/missing"], &[]),
            Err(ComposeError::UnknownModule {
                module: "b/missing".into(),
                by: "<roots>".into()
            })
        );
        assert_eq!(
            l.compose(&["b/pass"], &params[..1]),
            Err(ComposeError::MissingParameter {
                module: "b/pass".into(),
                name: "FORMAT".into()
            })
        );
        assert!(matches!(
            l.compose(&["b/pass"], &[params[0], params[1], ("FROMAT", "x")]),
            Err(ComposeError::UnusedParameter { name, .. }) if name == "FROMAT"
        ));
        let mut l = library(MODULES);
        l.replace("a/types", "#import b/other\nstruct T { x: {{TYPE}} }");
        assert_eq!(
            l.compose(&["b/other"], &[]),
            Err(ComposeError::ImportCycle {
                cycle: vec![
                    "b/other".into(),
                    "a/util".into(),
                    "a/types".into(),
                    "b/other".into()
                ]
            })
        );
        l.replace("a/types", "struct T { x: {{TYPE}} }");
        assert_eq!(
            l.compose(&["a/types"], &[("TYPE", "u32")]),
            Err(ComposeError::UndeclaredPlaceholder {
                module: "a/types".into(),
                name: "TYPE".into()
            })
        );
        l.replace("a/types", "#include a/util\nstruct T { x: u32 }");
        assert_eq!(
            l.compose(&["a/types"], &[]),
            Err(ComposeError::BadDirective {
                module: "a/types".into(),
                line: 1,
                text: "#include a/util".into()
            })
        );
        l.replace("a/types", "#import");
        assert!(matches!(
            l.compose(&["a/types"], &[]),
            Err(ComposeError::BadDirective { line: 1, .. })
        ));
        l.replace("a/types", "#param 1X");
        assert!(matches!(
            l.compose(&["a/types"], &[]),
            Err(ComposeError::BadDirective { line: 1, .. })
        ));
    }

    #[test]
    fn every_builtin_module_s_imports_resolve_without_a_loop() {
        let l = ShaderLibrary::builtin();
        for name in l.names() {
            let mut order = Vec::new();
            l.visit(name, "<roots>", &mut Vec::new(), &mut order)
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(order.last(), Some(&name));
        }
    }
}
