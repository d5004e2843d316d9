//! gRPC server reflection, v1 and v1alpha, for both servers.
//!
//! tonic-reflection's service is built per version from the descriptor
//! sets it is given, and each version knew only its own reflection file;
//! a symbol it did not know ended the whole stream with a status, where
//! the protocol answers an `ErrorResponse` inside the stream and goes on;
//! and a client gone before its answer was sent panicked the task. This
//! one answers every request of a stream in turn, from one table of files
//! and symbols that both versions share (each version's own reflection
//! file included), sends each file with the files it imports, and ends
//! when the client does. The generated message and service types are
//! tonic-reflection's; v1alpha's messages are v1's on the wire, so a
//! v1alpha request is read as v1 and its answer written back as v1alpha.

use std::collections::{HashMap, HashSet};
use std::pin::Pin;
use std::sync::Arc;

use prost::Message;
use prost_types::{DescriptorProto, FileDescriptorProto, FileDescriptorSet};
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::{Stream, StreamExt};
use tonic::{Request, Response, Status, Streaming};
use tonic_reflection::pb::{v1, v1alpha};
use v1::server_reflection_request::MessageRequest;
use v1::server_reflection_response::MessageResponse;

/// gRPC's NOT_FOUND and INVALID_ARGUMENT codes, as an `ErrorResponse`
/// carries them.
const NOT_FOUND: i32 = tonic::Code::NotFound as i32;
const INVALID_ARGUMENT: i32 = tonic::Code::InvalidArgument as i32;

/// Answers a stream may have waiting before its reader takes them.
const ANSWERS_IN_FLIGHT: usize = 4;

/// The v1 reflection service's name …
pub const V1_SERVICE_NAME: &str = "grpc.reflection.v1.ServerReflection";
/// … and v1alpha's, which many tools still ask first.
pub const V1ALPHA_SERVICE_NAME: &str = "grpc.reflection.v1alpha.ServerReflection";

/// A descriptor set that would not decode or names no file.
#[derive(Debug, thiserror::Error)]
#[error("reflection: {0}")]
pub struct ReflectionError(String);

/// What reflection describes: every file of the sets given, by name, and
/// the file each symbol (package-qualified message, enum, service,
/// method) is declared in.
#[derive(Debug)]
struct Descriptors {
    /// Each file encoded, and the names of the files it imports.
    files: HashMap<String, (Vec<u8>, Vec<String>)>,
    symbols: HashMap<String, String>,
    /// The services listed, as the server offers them.
    services: Vec<String>,
}

impl Descriptors {
    fn new(sets: &[&[u8]], services: &[&str]) -> Result<Self, ReflectionError> {
        let mut descriptors = Self {
            files: HashMap::new(),
            symbols: HashMap::new(),
            services: services.iter().map(|s| (*s).to_owned()).collect(),
        };
        let own = [v1::FILE_DESCRIPTOR_SET, v1alpha::FILE_DESCRIPTOR_SET];
        for encoded in sets.iter().chain(own.iter()) {
            let set = FileDescriptorSet::decode(*encoded)
                .map_err(|e| ReflectionError(format!("a descriptor set does not decode: {e}")))?;
            for file in set.file {
                descriptors.add(file)?;
            }
        }
        Ok(descriptors)
    }

    fn add(&mut self, file: FileDescriptorProto) -> Result<(), ReflectionError> {
        let name = file
            .name
            .clone()
            .ok_or_else(|| ReflectionError("a file descriptor has no name".into()))?;
        if self.files.contains_key(&name) {
            return Ok(());
        }
        let package = file.package.clone().unwrap_or_default();
        let qualified = |name: &str| {
            if package.is_empty() {
                name.to_owned()
            } else {
                format!("{package}.{name}")
            }
        };
        for message in &file.message_type {
            self.add_message(&name, &qualified(message.name()), message);
        }
        for kind in &file.enum_type {
            self.symbols.insert(qualified(kind.name()), name.clone());
        }
        for service in &file.service {
            let service_name = qualified(service.name());
            for method in &service.method {
                self.symbols
                    .insert(format!("{service_name}.{}", method.name()), name.clone());
            }
            self.symbols.insert(service_name, name.clone());
        }
        self.files
            .insert(name, (file.encode_to_vec(), file.dependency.clone()));
        Ok(())
    }

    fn add_message(&mut self, file: &str, qualified: &str, message: &DescriptorProto) {
        self.symbols.insert(qualified.to_owned(), file.to_owned());
        for nested in &message.nested_type {
            self.add_message(file, &format!("{qualified}.{}", nested.name()), nested);
        }
        for kind in &message.enum_type {
            self.symbols
                .insert(format!("{qualified}.{}", kind.name()), file.to_owned());
        }
    }

    /// The file named and every file it imports, transitively, each once,
    /// the file itself first.
    fn file_with_imports(&self, name: &str) -> Option<Vec<Vec<u8>>> {
        self.files.get(name)?;
        let mut out = Vec::new();
        let mut seen = HashSet::new();
        let mut queue = vec![name.to_owned()];
        while let Some(next) = queue.pop() {
            if !seen.insert(next.clone()) {
                continue;
            }
            // An import the sets do not hold is left out: the client asks
            // for it by name if it needs it, and is told it is not found.
            if let Some((encoded, imports)) = self.files.get(&next) {
                out.push(encoded.clone());
                queue.extend(imports.iter().rev().cloned());
            }
        }
        Some(out)
    }

    /// The answer to one request.
    fn answer(&self, request: Option<MessageRequest>) -> MessageResponse {
        let files = |found: Option<Vec<Vec<u8>>>, what: String| match found {
            Some(file_descriptor_proto) => {
                MessageResponse::FileDescriptorResponse(v1::FileDescriptorResponse {
                    file_descriptor_proto,
                })
            }
            None => error(NOT_FOUND, format!("{what} is not known to this server")),
        };
        match request {
            None => error(INVALID_ARGUMENT, "the request asks nothing".into()),
            Some(MessageRequest::FileByFilename(name)) => {
                files(self.file_with_imports(&name), format!("file {name:?}"))
            }
            Some(MessageRequest::FileContainingSymbol(symbol)) => {
                let symbol = symbol.trim_start_matches('.');
                let found = self
                    .symbols
                    .get(symbol)
                    .and_then(|file| self.file_with_imports(file));
                files(found, format!("symbol {symbol:?}"))
            }
            Some(MessageRequest::FileContainingExtension(request)) => error(
                NOT_FOUND,
                format!(
                    "extension {} of {:?}: this server's files declare no extensions",
                    request.extension_number, request.containing_type
                ),
            ),
            // No extensions, but the type is answered: grpcurl asks this of
            // every message and stops at an error.
            Some(MessageRequest::AllExtensionNumbersOfType(base_type_name)) => {
                let base = base_type_name.trim_start_matches('.');
                if self.symbols.contains_key(base) {
                    MessageResponse::AllExtensionNumbersResponse(v1::ExtensionNumberResponse {
                        base_type_name: base.to_owned(),
                        extension_number: Vec::new(),
                    })
                } else {
                    error(
                        NOT_FOUND,
                        format!("type {base:?} is not known to this server"),
                    )
                }
            }
            Some(MessageRequest::ListServices(_)) => {
                MessageResponse::ListServicesResponse(v1::ListServiceResponse {
                    service: self
                        .services
                        .iter()
                        .map(|name| v1::ServiceResponse { name: name.clone() })
                        .collect(),
                })
            }
        }
    }
}

fn error(code: i32, message: String) -> MessageResponse {
    MessageResponse::ErrorResponse(v1::ErrorResponse {
        error_code: code,
        error_message: message,
    })
}

/// The answers to each request of `requests` in turn, until the client
/// ends its side or goes; `convert` reads a request as v1, `back` writes
/// a v1 answer in the stream's own version.
fn answer_stream<Req, Resp>(
    descriptors: Arc<Descriptors>,
    mut requests: Streaming<Req>,
    convert: fn(Req) -> Result<v1::ServerReflectionRequest, Status>,
    back: fn(v1::ServerReflectionResponse) -> Result<Resp, Status>,
) -> ReceiverStream<Result<Resp, Status>>
where
    Req: Send + 'static,
    Resp: Send + 'static,
{
    let (tx, rx) = mpsc::channel(ANSWERS_IN_FLIGHT);
    tokio::spawn(async move {
        while let Some(request) = requests.next().await {
            let answer = request.and_then(convert).and_then(|request| {
                back(v1::ServerReflectionResponse {
                    valid_host: request.host.clone(),
                    message_response: Some(descriptors.answer(request.message_request.clone())),
                    original_request: Some(request),
                })
            });
            let failed = answer.is_err();
            // A client gone before its answer: nothing more to do.
            if tx.send(answer).await.is_err() || failed {
                return;
            }
        }
    });
    ReceiverStream::new(rx)
}

/// Reflection, one table for both versions.
#[derive(Debug, Clone)]
pub struct Reflection {
    descriptors: Arc<Descriptors>,
}

/// The answer stream of either version.
pub type AnswerStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

impl Reflection {
    /// Reflection of the files of `sets` (encoded `FileDescriptorSet`s;
    /// the reflection files of both versions are added), listing
    /// `services` as what the server offers.
    pub fn new(sets: &[&[u8]], services: &[&str]) -> Result<Self, ReflectionError> {
        Ok(Self {
            descriptors: Arc::new(Descriptors::new(sets, services)?),
        })
    }

    /// The v1 service, to add to a server.
    pub fn v1(&self) -> v1::server_reflection_server::ServerReflectionServer<Self> {
        v1::server_reflection_server::ServerReflectionServer::new(self.clone())
    }

    /// The v1alpha service, to add to a server.
    pub fn v1alpha(&self) -> v1alpha::server_reflection_server::ServerReflectionServer<Self> {
        v1alpha::server_reflection_server::ServerReflectionServer::new(self.clone())
    }
}

/// Re-encodes `message` as `T`: the two versions' messages are the same
/// on the wire.
fn recode<T: Message + Default>(message: &impl Message) -> Result<T, Status> {
    T::decode(message.encode_to_vec().as_slice())
        .map_err(|e| Status::internal(format!("reflection message: {e}")))
}

#[tonic::async_trait]
impl v1::server_reflection_server::ServerReflection for Reflection {
    type ServerReflectionInfoStream = AnswerStream<v1::ServerReflectionResponse>;

    async fn server_reflection_info(
        &self,
        request: Request<Streaming<v1::ServerReflectionRequest>>,
    ) -> Result<Response<Self::ServerReflectionInfoStream>, Status> {
        Ok(Response::new(Box::pin(answer_stream(
            self.descriptors.clone(),
            request.into_inner(),
            Ok,
            Ok,
        ))))
    }
}

#[tonic::async_trait]
impl v1alpha::server_reflection_server::ServerReflection for Reflection {
    type ServerReflectionInfoStream = AnswerStream<v1alpha::ServerReflectionResponse>;

    async fn server_reflection_info(
        &self,
        request: Request<Streaming<v1alpha::ServerReflectionRequest>>,
    ) -> Result<Response<Self::ServerReflectionInfoStream>, Status> {
        Ok(Response::new(Box::pin(answer_stream(
            self.descriptors.clone(),
            request.into_inner(),
            |r| recode(&r),
            |r| recode(&r),
        ))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn descriptors() -> Descriptors {
        Descriptors::new(
            &[
                crate::FILE_DESCRIPTOR_SET,
                tonic_health::pb::FILE_DESCRIPTOR_SET,
            ],
            &["deog.v1.MapService", V1_SERVICE_NAME],
        )
        .unwrap()
    }

    fn decoded(answer: MessageResponse) -> Vec<FileDescriptorProto> {
        match answer {
            MessageResponse::FileDescriptorResponse(files) => files
                .file_descriptor_proto
                .iter()
                .map(|f| FileDescriptorProto::decode(f.as_slice()).unwrap())
                .collect(),
            other => panic!("not files: {other:?}"),
        }
    }

    #[test]
    fn each_version_describes_both_reflection_files() {
        let d = descriptors();
        for symbol in [
            V1_SERVICE_NAME,
            V1ALPHA_SERVICE_NAME,
            "grpc.health.v1.Health",
        ] {
            let files =
                decoded(d.answer(Some(MessageRequest::FileContainingSymbol(symbol.into()))));
            assert!(
                files[0].service.iter().any(|s| symbol.ends_with(s.name())),
                "{symbol}: {:?}",
                files[0].name
            );
        }
    }

    #[test]
    fn a_file_comes_with_what_it_imports() {
        let d = descriptors();
        let files = decoded(d.answer(Some(MessageRequest::FileContainingSymbol(
            "deog.v1.MapService".into(),
        ))));
        let names: HashSet<_> = files.iter().map(|f| f.name().to_owned()).collect();
        for import in &files[0].dependency {
            assert!(
                names.contains(import) || !d.files.contains_key(import),
                "{import} missing from {names:?}"
            );
        }
        assert_eq!(names.len(), files.len(), "a file sent twice");
    }

    #[test]
    fn an_unknown_symbol_is_an_error_answer() {
        let d = descriptors();
        match d.answer(Some(MessageRequest::FileContainingSymbol("no.Such".into()))) {
            MessageResponse::ErrorResponse(e) => assert_eq!(e.error_code, NOT_FOUND),
            other => panic!("{other:?}"),
        }
        match d.answer(None) {
            MessageResponse::ErrorResponse(e) => assert_eq!(e.error_code, INVALID_ARGUMENT),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn services_listed_are_those_given_and_nested_messages_are_symbols() {
        let d = descriptors();
        match d.answer(Some(MessageRequest::ListServices(String::new()))) {
            MessageResponse::ListServicesResponse(list) => {
                let names: Vec<_> = list.service.iter().map(|s| s.name.as_str()).collect();
                assert_eq!(names, ["deog.v1.MapService", V1_SERVICE_NAME]);
            }
            other => panic!("{other:?}"),
        }
        assert!(
            d.symbols
                .contains_key("grpc.health.v1.HealthCheckResponse.ServingStatus")
        );
    }

    #[test]
    fn a_set_that_does_not_decode_is_refused() {
        assert!(Descriptors::new(&[&[0xff, 0xff, 0xff]], &[]).is_err());
    }
}
