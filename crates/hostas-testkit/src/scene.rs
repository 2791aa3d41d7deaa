//! Scene descriptions: the raw arrays an application would hand to Vulkan.

use hostas::{
    AccelerationStructure, Affine, BuildGeometryInfo, BuildRangeInfo, Device, Geometry, Instance,
    InstancesData, vk,
};

/// One geometry of a bottom-level structure.
#[derive(Clone, Debug)]
pub enum GeometryDesc {
    /// Indexed or not (`indices` empty = non-indexed, 3 vertices per triangle).
    Triangles {
        positions: Vec<[f32; 3]>,
        indices: Vec<u32>,
        transform: Option<Affine>,
        flags: vk::GeometryFlagsKHR,
    },
    /// Boxes as six floats (min xyz, max xyz); `min x = NaN` marks an inactive box.
    Aabbs {
        boxes: Vec<[f32; 6]>,
        flags: vk::GeometryFlagsKHR,
    },
}

impl GeometryDesc {
    pub fn primitive_count(&self) -> u32 {
        match self {
            GeometryDesc::Triangles {
                positions, indices, ..
            } => {
                if indices.is_empty() {
                    positions.len() as u32 / 3
                } else {
                    indices.len() as u32 / 3
                }
            }
            GeometryDesc::Aabbs { boxes, .. } => boxes.len() as u32,
        }
    }
    pub fn flags(&self) -> vk::GeometryFlagsKHR {
        match self {
            GeometryDesc::Triangles { flags, .. } | GeometryDesc::Aabbs { flags, .. } => *flags,
        }
    }
    /// Triangle `i` as the spec defines it (geometry transform applied), `None` if inactive.
    pub fn triangle(&self, i: u32) -> Option<[[f32; 3]; 3]> {
        let GeometryDesc::Triangles {
            positions,
            indices,
            transform,
            ..
        } = self
        else {
            return None;
        };
        let idx = |k: usize| {
            if indices.is_empty() {
                3 * i as usize + k
            } else {
                indices[3 * i as usize + k] as usize
            }
        };
        let v = [positions[idx(0)], positions[idx(1)], positions[idx(2)]];
        if v.iter().any(|p| p[0].is_nan()) {
            return None;
        }
        Some(match transform {
            Some(t) => v.map(|p| t.point(p)),
            None => v,
        })
    }
}

#[derive(Clone, Debug)]
pub struct BlasDesc {
    pub geometries: Vec<GeometryDesc>,
}

#[derive(Clone, Debug)]
pub struct InstanceDesc {
    pub transform: Affine,
    pub custom_index: u32,
    pub mask: u8,
    pub sbt_record_offset: u32,
    pub flags: vk::GeometryInstanceFlagsKHR,
    /// Index into `SceneDesc::blases`; `None` = inactive instance (reference 0).
    pub blas: Option<usize>,
}

#[derive(Clone, Debug)]
pub struct SceneDesc {
    pub blases: Vec<BlasDesc>,
    pub instances: Vec<InstanceDesc>,
}

/// A scene built on a device.
pub struct BuiltScene {
    pub blases: Vec<AccelerationStructure>,
    pub tlas: AccelerationStructure,
}

/// Owned bytes of one geometry, kept alive while the build reads them.
struct GeometryBytes {
    vertices: Vec<u8>,
    indices: Vec<u8>,
    transform: Vec<u8>,
    boxes: Vec<u8>,
}

fn geometry_bytes(g: &GeometryDesc) -> GeometryBytes {
    match g {
        GeometryDesc::Triangles {
            positions,
            indices,
            transform,
            ..
        } => GeometryBytes {
            vertices: bytemuck::cast_slice(positions).to_vec(),
            indices: bytemuck::cast_slice(indices).to_vec(),
            transform: transform
                .map(|t| bytemuck::cast_slice(&t.to_rows()).to_vec())
                .unwrap_or_default(),
            boxes: vec![],
        },
        GeometryDesc::Aabbs { boxes, .. } => GeometryBytes {
            vertices: vec![],
            indices: vec![],
            transform: vec![],
            boxes: bytemuck::cast_slice(boxes).to_vec(),
        },
    }
}

fn geometry<'a>(g: &GeometryDesc, b: &'a GeometryBytes) -> Geometry<'a> {
    match g {
        GeometryDesc::Triangles {
            positions,
            indices,
            transform,
            flags,
        } => Geometry::triangles(
            hostas::TrianglesData {
                vertex_format: vk::Format::R32G32B32_SFLOAT,
                vertex_data: &b.vertices,
                vertex_stride: 12,
                max_vertex: (positions.len() as u32).saturating_sub(1),
                index_type: if indices.is_empty() {
                    vk::IndexType::NONE_KHR
                } else {
                    vk::IndexType::UINT32
                },
                index_data: if indices.is_empty() {
                    None
                } else {
                    Some(&b.indices)
                },
                transform_data: transform.map(|_| &b.transform[..]),
            },
            *flags,
        ),
        GeometryDesc::Aabbs { flags, .. } => Geometry::aabbs(
            hostas::AabbsData {
                data: &b.boxes,
                stride: 24,
            },
            *flags,
        ),
    }
}

impl BlasDesc {
    /// Calls `f` with the geometries and ranges an application would pass to Vulkan for this
    /// description (one range per geometry, every primitive).
    pub fn with_inputs<R>(&self, f: impl FnOnce(&[Geometry], &[BuildRangeInfo]) -> R) -> R {
        let bytes: Vec<GeometryBytes> = self.geometries.iter().map(geometry_bytes).collect();
        let geoms: Vec<Geometry> = self
            .geometries
            .iter()
            .zip(&bytes)
            .map(|(g, b)| geometry(g, b))
            .collect();
        let ranges: Vec<BuildRangeInfo> = self
            .geometries
            .iter()
            .map(|g| BuildRangeInfo {
                primitive_count: g.primitive_count(),
                ..Default::default()
            })
            .collect();
        f(&geoms, &ranges)
    }

    /// Builds (mode BUILD) with `flags` into a new structure.
    pub fn build(
        &self,
        device: &Device,
        flags: vk::BuildAccelerationStructureFlagsKHR,
    ) -> hostas::Result<AccelerationStructure> {
        self.with_inputs(|geoms, ranges| {
            hostas::quick::build(
                device,
                vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                flags,
                geoms,
                ranges,
            )
        })
    }

    /// Updates `src` into `dst` (which may be `src`) with this description's data.
    pub fn update(
        &self,
        device: &Device,
        flags: vk::BuildAccelerationStructureFlagsKHR,
        src: AccelerationStructure,
        dst: AccelerationStructure,
    ) -> hostas::Result<()> {
        self.with_inputs(|geoms, ranges| {
            let counts: Vec<u32> = ranges.iter().map(|r| r.primitive_count).collect();
            let mut info = BuildGeometryInfo {
                ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                flags,
                mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
                src: Some(src),
                dst: Some(dst),
                geometries: geoms,
                scratch: None,
            };
            let sizes =
                device.build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &info, &counts)?;
            let mut scratch = vec![0u8; sizes.update_scratch_size as usize];
            info.scratch = Some(&mut scratch);
            device.build_acceleration_structures(&mut [info], &[ranges])
        })
    }
}

impl InstanceDesc {
    pub fn identity(blas: usize) -> InstanceDesc {
        InstanceDesc {
            transform: Affine::IDENTITY,
            custom_index: 0,
            mask: 0xff,
            sbt_record_offset: 0,
            flags: vk::GeometryInstanceFlagsKHR::empty(),
            blas: Some(blas),
        }
    }
    pub fn to_instance(&self, blases: &[AccelerationStructure]) -> Instance {
        Instance {
            transform: self.transform,
            custom_index: self.custom_index,
            mask: self.mask,
            sbt_record_offset: self.sbt_record_offset,
            flags: self.flags,
            acceleration_structure_reference: self.blas.map_or(0, |b| blases[b].raw()),
        }
    }
}

impl SceneDesc {
    /// Builds every BLAS with `blas_flags` and the TLAS with `tlas_flags`.
    pub fn build(
        &self,
        device: &Device,
        blas_flags: vk::BuildAccelerationStructureFlagsKHR,
        tlas_flags: vk::BuildAccelerationStructureFlagsKHR,
    ) -> hostas::Result<BuiltScene> {
        let blases = self
            .blases
            .iter()
            .map(|b| b.build(device, blas_flags))
            .collect::<hostas::Result<Vec<_>>>()?;
        let tlas = self.build_tlas(device, &blases, tlas_flags)?;
        Ok(BuiltScene { blases, tlas })
    }

    pub fn build_tlas(
        &self,
        device: &Device,
        blases: &[AccelerationStructure],
        flags: vk::BuildAccelerationStructureFlagsKHR,
    ) -> hostas::Result<AccelerationStructure> {
        let bytes: Vec<u8> = self
            .instances
            .iter()
            .flat_map(|i| i.to_instance(blases).encode())
            .collect();
        let g = Geometry::instances(InstancesData::Array(&bytes), vk::GeometryFlagsKHR::empty());
        let range = BuildRangeInfo {
            primitive_count: self.instances.len() as u32,
            ..Default::default()
        };
        hostas::quick::build(
            device,
            vk::AccelerationStructureTypeKHR::TOP_LEVEL,
            flags,
            &[g],
            &[range],
        )
    }
}
