//! The API reference of the contract as markdown, generated from the compiled descriptors (with their
//! source comments), so that it cannot drift from the `.proto` files. The build writes it beside the
//! descriptor set; a test compares it with `docs/api-reference.md` and fails on any service, method,
//! message, field, enum or enum value without a comment.

use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{DescriptorProto, EnumDescriptorProto, FileDescriptorProto, FileDescriptorSet};
use std::collections::HashMap;

/// Field numbers of `FileDescriptorProto` and `DescriptorProto` used in source-location paths.
mod path {
    pub const FILE_MESSAGE: i32 = 4;
    pub const FILE_ENUM: i32 = 5;
    pub const FILE_SERVICE: i32 = 6;
    pub const MESSAGE_FIELD: i32 = 2;
    pub const MESSAGE_NESTED: i32 = 3;
    pub const MESSAGE_ENUM: i32 = 4;
    pub const ENUM_VALUE: i32 = 2;
    pub const SERVICE_METHOD: i32 = 2;
}

/// The reference of the files in `set` whose package is `package`, and the items that carry no comment
/// (each named as `package.Message.field`); the reference is only complete when that list is empty.
pub fn api_reference(set: &FileDescriptorSet, package: &str) -> (String, Vec<String>) {
    let mut writer = Writer { out: String::new(), undocumented: Vec::new() };
    writer.line(&format!("# API reference: `{package}`"));
    writer.line("");
    writer.line(
        "Generated from `proto/fastrack/v1/*.proto` by the `fastrack-proto` build; do not edit by hand (a test \
         compares this file with the contract: `FASTRACK_WRITE_API_REFERENCE=1 cargo test --workspace --test api_reference` \
         rewrites it). Semantics, errors and examples: [api.md](api.md).",
    );
    let files: Vec<&FileDescriptorProto> = set.file.iter().filter(|f| f.package() == package).collect();
    for file in &files {
        let comments = Comments::of(file);
        writer.line("");
        writer.line(&format!("## `{}`", file.name()));
        for (i, service) in file.service.iter().enumerate() {
            let at = child(&[], path::FILE_SERVICE, i);
            writer.heading(
                &format!("Service `{}`", service.name()),
                comments.get(&at),
                &format!("{package}.{}", service.name()),
            );
            writer.line("| method | request | response | description |");
            writer.line("|---|---|---|---|");
            for (j, method) in service.method.iter().enumerate() {
                let name = format!("{package}.{}.{}", service.name(), method.name());
                let text = writer.documented(comments.get(&child(&at, path::SERVICE_METHOD, j)), &name);
                let stream = |streaming: bool| if streaming { "stream " } else { "" };
                writer.line(&format!(
                    "| `{}` | {}{} | {}{} | {} |",
                    method.name(),
                    stream(method.client_streaming()),
                    type_link(method.input_type()),
                    stream(method.server_streaming()),
                    type_link(method.output_type()),
                    cell(&text)
                ));
            }
        }
        for (i, message) in file.message_type.iter().enumerate() {
            writer.message(message, &comments, &child(&[], path::FILE_MESSAGE, i), package);
        }
        for (i, en) in file.enum_type.iter().enumerate() {
            writer.enumeration(en, &comments, &child(&[], path::FILE_ENUM, i), package);
        }
    }
    (writer.out, writer.undocumented)
}

/// Leading comments by source-location path.
struct Comments(HashMap<Vec<i32>, String>);

impl Comments {
    fn of(file: &FileDescriptorProto) -> Self {
        let locations = file.source_code_info.as_ref().map_or(&[][..], |info| &info.location[..]);
        let comments = locations
            .iter()
            .filter_map(|l| {
                let text = l.leading_comments().trim();
                (!text.is_empty()).then(|| (l.path.clone(), unwrap_comment(text)))
            })
            .collect();
        Self(comments)
    }

    fn get(&self, path: &[i32]) -> Option<&str> {
        self.0.get(path).map(String::as_str)
    }
}

/// The source-location path of item `index` of kind `kind` inside the item at `at`.
fn child(at: &[i32], kind: i32, index: usize) -> Vec<i32> {
    let mut path = at.to_vec();
    path.extend([kind, index as i32]);
    path
}

/// A comment's lines joined into one paragraph (blank comment lines become paragraph breaks).
fn unwrap_comment(text: &str) -> String {
    text.split("\n\n")
        .map(|paragraph| paragraph.lines().map(str::trim).collect::<Vec<_>>().join(" "))
        .collect::<Vec<_>>()
        .join("\n\n")
}

/// Text fit for one table cell.
fn cell(text: &str) -> String {
    text.replace("\n\n", "<br><br>").replace('|', "\\|")
}

/// `.fastrack.v1.ModelRef` as a link to its section.
fn type_link(full_name: &str) -> String {
    let short = full_name.rsplit('.').next().unwrap_or(full_name);
    format!("[`{short}`](#{})", short.to_lowercase())
}

struct Writer {
    out: String,
    undocumented: Vec<String>,
}

impl Writer {
    fn line(&mut self, text: &str) {
        self.out.push_str(text);
        self.out.push('\n');
    }

    /// The comment, or a marker and an entry in the undocumented list.
    fn documented(&mut self, comment: Option<&str>, name: &str) -> String {
        match comment {
            Some(text) => text.to_string(),
            None => {
                self.undocumented.push(name.to_string());
                "(undocumented)".to_string()
            }
        }
    }

    fn heading(&mut self, title: &str, comment: Option<&str>, name: &str) {
        let text = self.documented(comment, name);
        self.line("");
        self.line(&format!("### {title}"));
        self.line("");
        self.line(&text);
        self.line("");
    }

    fn message(&mut self, message: &DescriptorProto, comments: &Comments, at: &[i32], scope: &str) {
        let name = format!("{scope}.{}", message.name());
        if message.options.as_ref().is_some_and(|o| o.map_entry()) {
            return;
        }
        let anchor_name = message.name();
        self.heading(&format!("`{anchor_name}`"), comments.get(at), &name);
        if message.field.is_empty() {
            self.line("No fields.");
        } else {
            self.line("| field | number | type | description |");
            self.line("|---|---|---|---|");
            for (k, field) in message.field.iter().enumerate() {
                let at_field = child(at, path::MESSAGE_FIELD, k);
                let text = self.documented(comments.get(&at_field), &format!("{name}.{}", field.name()));
                let oneof = field
                    .oneof_index
                    .filter(|_| !field.proto3_optional())
                    .and_then(|i| message.oneof_decl.get(i as usize))
                    .map_or(String::new(), |o| format!(" (one of `{}`)", o.name()));
                self.line(&format!(
                    "| `{}` | {} | {}{oneof} | {} |",
                    field.name(),
                    field.number(),
                    field_type(field, message),
                    cell(&text)
                ));
            }
        }
        for (k, nested) in message.nested_type.iter().enumerate() {
            self.message(nested, comments, &child(at, path::MESSAGE_NESTED, k), &name);
        }
        for (k, en) in message.enum_type.iter().enumerate() {
            self.enumeration(en, comments, &child(at, path::MESSAGE_ENUM, k), &name);
        }
    }

    fn enumeration(&mut self, en: &EnumDescriptorProto, comments: &Comments, at: &[i32], scope: &str) {
        let name = format!("{scope}.{}", en.name());
        self.heading(&format!("`{}`", en.name()), comments.get(at), &name);
        self.line("| enum value | number | description |");
        self.line("|---|---|---|");
        for (k, value) in en.value.iter().enumerate() {
            let text =
                self.documented(comments.get(&child(at, path::ENUM_VALUE, k)), &format!("{name}.{}", value.name()));
            self.line(&format!("| `{}` | {} | {} |", value.name(), value.number(), cell(&text)));
        }
    }
}

/// The field's type as written in the `.proto` file, message and enum types linked.
fn field_type(field: &prost_types::FieldDescriptorProto, message: &DescriptorProto) -> String {
    let base = match field.r#type() {
        Type::Message | Type::Enum => {
            let entry = message.nested_type.iter().find(|n| {
                n.options.as_ref().is_some_and(|o| o.map_entry())
                    && field.type_name().ends_with(&format!(".{}", n.name()))
            });
            if let Some(entry) = entry {
                let key = entry.field.first().map_or(String::new(), |f| field_type(f, entry));
                let value = entry.field.get(1).map_or(String::new(), |f| field_type(f, entry));
                return format!("map<{key}, {value}>");
            }
            type_link(field.type_name())
        }
        scalar => format!("`{}`", scalar.as_str_name().trim_start_matches("TYPE_").to_lowercase()),
    };
    match field.label() {
        Label::Repeated => format!("repeated {base}"),
        _ if field.proto3_optional() => format!("optional {base}"),
        _ => base,
    }
}
