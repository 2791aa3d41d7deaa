//! Wavefront OBJ through `tobj`, with a second look at the text to say where an error is.

use std::path::Path;

use tobj::LoadError;

use super::{Location, MeshError, Triangles};

pub(super) fn parse(path: &Path, data: &[u8]) -> Result<Triangles, MeshError> {
    let options = tobj::LoadOptions {
        triangulate: true,
        // Keep position indices as written; texture and normal indices do not matter here.
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    // Materials are not needed: answer every `mtllib` with an empty library.
    let (models, _materials) =
        tobj::load_obj_buf(&mut &data[..], &options, |_| Ok(Default::default()))
            .map_err(|err| locate_error(path, data, &err))?;

    let vertex_total: usize = models.iter().map(|m| m.mesh.positions.len() / 3).sum();
    if u32::try_from(vertex_total).is_err() {
        return Err(MeshError::format(
            path,
            Location::File,
            "too many vertices for 32-bit indices",
        ));
    }
    let triangle_total: usize = models.iter().map(|m| m.mesh.indices.len() / 3).sum();
    let mut positions = Vec::with_capacity(vertex_total);
    let mut indices = Vec::with_capacity(triangle_total);
    for model in &models {
        // Cannot truncate: the total was checked above.
        let base = positions.len() as u32;
        positions.extend(
            model
                .mesh
                .positions
                .chunks_exact(3)
                .map(|p| [p[0], p[1], p[2]]),
        );
        // tobj has checked every index against the model's positions.
        indices.extend(
            model
                .mesh
                .indices
                .chunks_exact(3)
                .map(|t| [base + t[0], base + t[1], base + t[2]]),
        );
    }
    Ok((positions, indices))
}

/// Turns a `tobj` error, which carries no position, into a [`MeshError`] by scanning the
/// text for the first line that fails the same check.
fn locate_error(path: &Path, data: &[u8], err: &LoadError) -> MeshError {
    // Numbers of `v`, `vt` and `vn` lines so far, for resolving face indices.
    let mut counts = [0u64; 3];
    let mut face: u64 = 0;
    for (number, raw) in data.split(|&b| b == b'\n').enumerate() {
        let location = Location::Line(number + 1);
        let Ok(line) = std::str::from_utf8(raw) else {
            if *err == LoadError::ReadError {
                return MeshError::format(path, location, "line is not valid UTF-8");
            }
            continue;
        };
        let mut words = line.split_whitespace();
        let keyword = words.next();
        let problem = match (keyword, err) {
            (
                Some("v"),
                LoadError::PositionParseError
                | LoadError::ScalingByZeroError
                | LoadError::ColorParseError,
            ) => vertex_problem(words.clone()),
            (Some("vt"), LoadError::TexcoordParseError) => numbers_problem(words.clone(), 2),
            (Some("vn"), LoadError::NormalParseError) => numbers_problem(words.clone(), 3),
            (Some("f" | "l"), LoadError::FaceParseError) => face_syntax_problem(words.clone()),
            (Some("f"), LoadError::InvalidPolygon) if words.clone().next().is_none() => {
                Some("face without vertices".to_owned())
            }
            _ => None,
        };
        if let Some(message) = problem {
            return MeshError::format(path, location, message);
        }
        match keyword {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            // tobj ignores points and lines, so only polygons can hold a bad index.
            Some("f") if words.clone().nth(2).is_some() => {
                if let Some(error) = face_index_problem(path, &location, err, words, counts, face) {
                    return error;
                }
                face += 1;
            }
            Some("f") => face += 1,
            _ => {}
        }
    }
    let message = match err {
        LoadError::FaceColorOutOfBounds => {
            "some vertices have colours and others not, which tobj rejects".to_owned()
        }
        _ => format!("invalid OBJ: {err}"),
    };
    MeshError::format(path, Location::File, message)
}

/// Checks the indices of face `face` (the words after `f`) for the out-of-bounds error
/// `err`, given the numbers of positions, texture coordinates and normals before it.
fn face_index_problem<'a>(
    path: &Path,
    location: &Location,
    err: &LoadError,
    words: impl Iterator<Item = &'a str>,
    counts: [u64; 3],
    face: u64,
) -> Option<MeshError> {
    const KINDS: [(LoadError, &str); 3] = [
        (LoadError::FaceVertexOutOfBounds, "vertex"),
        (LoadError::FaceTexCoordOutOfBounds, "texture coordinate"),
        (LoadError::FaceNormalOutOfBounds, "normal"),
    ];
    let slot = KINDS.iter().position(|(kind, _)| kind == err)?;
    for word in words {
        let part = word.split('/').nth(slot).unwrap_or("");
        if part.is_empty() {
            if slot == 0 {
                let message = format!("face {face}: {word:?} has no vertex index");
                return Some(MeshError::format(path, location.clone(), message));
            }
            continue;
        }
        let Ok(index) = part.parse::<i64>() else {
            continue;
        };
        let count = counts[slot];
        let resolved = if index < 0 {
            count as i64 + index
        } else {
            index - 1
        };
        if resolved >= 0 && (resolved as u64) < count {
            continue;
        }
        return Some(if slot == 0 {
            MeshError::IndexOutOfRange {
                path: path.to_owned(),
                location: location.clone(),
                face,
                index,
                vertex_count: count,
            }
        } else {
            let what = KINDS[slot].1;
            let message =
                format!("face {face} refers to {what} {index}, but there are only {count}");
            MeshError::format(path, location.clone(), message)
        });
    }
    None
}

/// Mirrors tobj's checks of a `v` line: three numbers, then nothing, a non-zero `w`, or
/// an RGB colour.
fn vertex_problem<'a>(words: impl Iterator<Item = &'a str> + Clone) -> Option<String> {
    if let Some(problem) = numbers_problem(words.clone(), 3) {
        return Some(problem);
    }
    let rest: Vec<&str> = words.skip(3).collect();
    match rest.as_slice() {
        [] | [_, _, _] => None,
        [w] => match w.parse::<f32>() {
            Ok(0.0) => Some("vertex with w = 0".to_owned()),
            Ok(_) => None,
            Err(_) => Some(format!("bad vertex w {w:?}")),
        },
        _ => Some(format!(
            "vertex with {} values (expected 3, 4 or 6)",
            rest.len() + 3
        )),
    }
}

fn numbers_problem<'a>(mut words: impl Iterator<Item = &'a str>, count: usize) -> Option<String> {
    for _ in 0..count {
        match words.next() {
            None => return Some(format!("expected {count} numbers")),
            Some(word) if word.parse::<f32>().is_err() => {
                return Some(format!("expected a number, found {word:?}"));
            }
            Some(_) => {}
        }
    }
    None
}

fn face_syntax_problem<'a>(words: impl Iterator<Item = &'a str>) -> Option<String> {
    for word in words {
        let parts: Vec<&str> = word.split('/').collect();
        let well_formed = parts.len() <= 3
            && parts
                .iter()
                .all(|part| part.is_empty() || part.parse::<isize>().is_ok());
        if !well_formed {
            return Some(format!("bad face vertex {word:?}"));
        }
    }
    None
}
